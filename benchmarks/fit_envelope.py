"""Time of `manual.fit_envelope` (run at POSCTL's, OFFBOARD's and HOLD's entry, in the
control loop) on both vehicle files: .venv/bin/python -m benchmarks.fit_envelope"""

from __future__ import annotations

import timeit
from pathlib import Path

from common.config import load_vehicle
from fcu import manual, offboard

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    level = (1.0, 0.0, 0.0, 0.0)
    for name in ("hexa_tilted", "hexa_planar"):
        vehicle = load_vehicle(ROOT / "config" / "vehicles" / f"{name}.toml")
        for mode, s, any_axis in (("POSCTL", manual.StickSettings(), False),
                                  ("OFFBOARD/HOLD", offboard.limits(manual.StickSettings()),
                                   True)):
            manual.fit_envelope(s, vehicle, level, any_axis)
            n = 10
            t = timeit.timeit(lambda s=s, a=any_axis, v=vehicle: manual.fit_envelope(
                s, v, level, a), number=n) / n
            f = manual.fit_envelope(s, vehicle, level, any_axis)
            print(f"{name:12s} {mode:14s} {t * 1e3:6.1f} ms  acc {f.acc_xy_m_s2:.3f} m/s^2, "
                  f"rotation {f.yaw_rate_deg_s:.1f} deg/s")


if __name__ == "__main__":
    main()
