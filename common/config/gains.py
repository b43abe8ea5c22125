"""The tracker's gains (eq. 30 and eq. 33) from TOML (config/gains/), checked against the
Routh-Hurwitz condition of the paper's eqs. (20)-(23): k_p, k_d > 0, k_i >= 0, k_p k_d > k_i.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.config.reader import ConfigError, Table, read_toml

Vec3 = tuple[float, float, float]


DAMPING_CHOICES = ("log_rate", "twist")


@dataclass(frozen=True)
class Gains:
    """Per-part gains of eq. (3): real part (attitude) and dual part (position), per axis.

    `damping` selects D in eq. (16): "log_rate" = 2 k_d . (ln q_e)' (the paper's PID law),
    "twist" = k_d . xi_e (Wang & Yu's damping, used by the PD baseline of eq. 33).
    """

    kp_r: Vec3
    kp_d: Vec3
    ki_r: Vec3
    ki_d: Vec3
    kd_r: Vec3
    kd_d: Vec3
    damping: str = "log_rate"

    @property
    def is_pd(self) -> bool:
        return not any(self.ki_r) and not any(self.ki_d)


GAIN_PARTS = ("kp_r", "kp_d", "ki_r", "ki_d", "kd_r", "kd_d")


def check_stability(gains: Gains) -> None:
    """Routh-Hurwitz for s^3 + k_d s^2 + k_p s + k_i per axis and part (eqs. 20-25)."""
    axes = "xyz"
    for part in ("r", "d"):
        kp = getattr(gains, f"kp_{part}")
        ki = getattr(gains, f"ki_{part}")
        kd = getattr(gains, f"kd_{part}")
        for a in range(3):
            tag = f"[{axes[a]}]"
            if not kp[a] > 0.0:
                raise ConfigError(f"gain kp_{part}{tag} = {kp[a]} violates k_p > 0")
            if not kd[a] > 0.0:
                raise ConfigError(f"gain kd_{part}{tag} = {kd[a]} violates k_d > 0")
            if not ki[a] >= 0.0:
                raise ConfigError(f"gain ki_{part}{tag} = {ki[a]} violates k_i >= 0")
            if not kp[a] * kd[a] > ki[a]:
                raise ConfigError(
                    f"gain ki_{part}{tag} = {ki[a]} violates k_p k_d > k_i "
                    f"(k_p k_d = {kp[a] * kd[a]})")


def parse_gains(data: dict[str, Any], source: str) -> Gains:
    t = Table(data, source)
    values: dict[str, Any] = {}
    for key in GAIN_PARTS:
        default = (0.0, 0.0, 0.0) if key.startswith("ki") else ...
        values[key] = t.numbers(key, 3, default)
    gains = Gains(**values, damping=t.string("damping", "log_rate", choices=DAMPING_CHOICES))
    t.finish()
    try:
        check_stability(gains)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None
    return gains


def load_gains(path: str | Path) -> Gains:
    path = Path(path)
    return parse_gains(read_toml(path), str(path))
