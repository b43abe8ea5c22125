"""The tracker's gains (eq. 30 and eq. 33) from TOML (config/gains/), checked against the
Routh-Hurwitz condition of the paper's eqs. (20)-(23): k_p, k_d > 0, k_i >= 0, k_p k_d > k_i.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.config.keys import Key, KeyTable
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

_PART = {"r": "real part (attitude)", "d": "dual part (position)"}
_TERM = {"kp": "proportional gain k_p", "ki": "integral gain k_i", "kd": "damping gain k_d"}
_RULE = {"kp": "each > 0", "ki": "each >= 0 and < k_p k_d", "kd": "each > 0"}

GAIN_KEYS = KeyTable("", (
    *(Key(key, "numbers", f"{_TERM[key[:2]]} per axis, {_PART[key[-1]]}",
          default=(0.0, 0.0, 0.0) if key.startswith("ki") else ...,
          range_doc=_RULE[key[:2]])
      for key in GAIN_PARTS),
    Key("damping", "string", "D in eq. (16): `log_rate` = 2 k_d . (ln q_e)' (the paper's "
        "PID law), `twist` = k_d . xi_e (the PD baseline's)", default="log_rate",
        choices=DAMPING_CHOICES),
))


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
    values = {key: GAIN_KEYS[key].read(t) for key in GAIN_PARTS}
    gains = Gains(**values, damping=GAIN_KEYS["damping"].read(t))
    t.finish()
    try:
        check_stability(gains)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None
    return gains


def load_gains(path: str | Path) -> Gains:
    path = Path(path)
    return parse_gains(read_toml(path), str(path))
