"""`common.process.realtime.schedule_loop` freezes what was built before the loop out of the garbage
collector's full collections (`gc.freeze`), whether or not SCHED_FIFO is granted."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_schedule_loop_freezes_what_was_built_before_the_loop():
    code = ("import gc; from common.process.realtime import schedule_loop; "
            "n = gc.get_freeze_count(); "
            "schedule_loop('prog', 0); print(n, gc.get_freeze_count())")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, timeout=60, check=True).stdout.split()
    assert out[:4] == ["prog:", "loop", "at", "normal"]
    before, after = int(out[-2]), int(out[-1])
    assert before == 0 and after > 1000
