"""A full parameter list goes out LIST_BURST at a time, one burst per housekeeping tick, so
it never holds the control loop up; every parameter once, in order, to the link that
asked; a request again starts that link's list again."""

from __future__ import annotations

from pathlib import Path

from common.config.scenario import load_gains
from fcu.edge.gcs_params import LIST_BURST, ParamService
from fcu.params import SPECS, ParamStore

ROOT = Path(__file__).resolve().parents[2]


def test_a_parameter_list_goes_out_a_burst_per_tick_in_order():
    sent: list[tuple[int, int | None]] = []
    service = ParamService(ParamStore(load_gains(ROOT / "config/gains/pid_eq30.toml")),
                           lambda msg, index: sent.append((msg.param_index,
                                                                          index)),
                           lambda *_: None, lambda: False)
    service.request_list(1)
    assert sent == []  # nothing inside the message's handling
    service.tick()
    assert sent == [(i, 1) for i in range(LIST_BURST)]
    service.request_list(0)
    while service.lists:
        service.tick()
    to_1 = [i for i, index in sent if index == 1]
    to_0 = [i for i, index in sent if index == 0]
    assert to_1 == to_0 == list(range(len(SPECS)))
    service.request_list(0)
    service.tick()
    service.request_list(0)  # again: from the start
    service.tick()
    assert [i for i, index in sent if index == 0][-2 * LIST_BURST:] == \
        [*range(LIST_BURST), *range(LIST_BURST)]
