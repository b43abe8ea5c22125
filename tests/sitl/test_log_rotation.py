"""Log rotation (SIGHUP to `fcu`, as logrotate sends it): the onboard log in use ends
complete, a log still at its path is set aside as onboard.1.ulg (nothing overwritten), a
new one starts at the path, and the FCU flies on; both are ULogs pyulog reads."""

from __future__ import annotations

import signal

from pyulog import ULog

from .conftest import launch, stop
from .waits import until


def _messages(path) -> list[str]:
    return [m.message for m in ULog(str(path)).logged_messages]


def test_sighup_ends_the_onboard_log_and_starts_the_next(tmp_path):
    """Given SIGHUP twice to a running FCU (the first log left where it is, the second
    renamed by the user first), then onboard.1.ulg and the renamed file are complete logs
    ending before the new file began, nothing is overwritten, and the FCU is still alive
    and answering."""
    s = launch(tmp_path)
    try:
        fcu = s.procs["fcu"]
        log = tmp_path / "onboard.ulg"
        fcu.send_signal(signal.SIGHUP)
        until(lambda: (tmp_path / "onboard.1.ulg").exists() and log.exists(),
              "onboard.1.ulg set aside and a new onboard.ulg", 20.0)
        until(lambda: s.session.recv(["STATUSTEXT"], timeout=0.5), "a STATUSTEXT", 20.0)
        renamed = tmp_path / "kept.ulg"
        until(lambda: log.stat().st_size > 0, "the new log's header", 20.0)
        log.rename(renamed)
        fcu.send_signal(signal.SIGHUP)
        until(lambda: log.exists(), "a third onboard.ulg", 20.0)
        assert not (tmp_path / "onboard.2.ulg").exists()  # the renamed one was left alone
        assert fcu.poll() is None
        assert s.wait_for(["HEARTBEAT"], timeout=10.0) is not None
    finally:
        s.session.close()
        stop(s.procs)
    first, second, third = tmp_path / "onboard.1.ulg", renamed, log
    assert "onboard log: a new file (onboard.1.ulg kept)" in _messages(second)
    assert "onboard log: a new file" in _messages(third)
    for path in (first, second, third):
        ULog(str(path))  # complete and readable
