"""Ground alignment: the stationary window of IMU blocks that initialises the filter.

The IMU stream is cut into blocks of align_block_s; a block is still when each axis' sd is
within align_noise_factor of the sensor noise, |mean gyro| is below align_gyro_max_rad_s,
|mean f| is near g and the mean f stays within align_accel_change_m_s2 of the window's. The
window keeps align_time_s of still blocks; its mean gyro is the initial gyro bias.
"""

from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple

from common.quaternion import Vec3
from fcu.estimator.inputs import ImuInput
from fcu.estimator.settings import EstimatorSettings


class Block(NamedTuple):
    n: int
    sw: Vec3  # sum of gyro samples
    sf: Vec3  # sum of accel samples


class AlignWindow:
    """The still blocks seen so far, and the block being summed."""

    def __init__(self, settings: EstimatorSettings) -> None:
        self.settings = settings
        self._g = settings.gravity_m_s2
        self._block_us = round(settings.align_block_s * 1e6)
        self._align_us = round(settings.align_time_s * 1e6)
        self.blocks: deque[Block] = deque()
        self._blk_t0 = -1
        self._clear_block()

    def _clear_block(self) -> None:
        self._blk_n = 0
        self._blk_sw = [0.0, 0.0, 0.0]
        self._blk_sw2 = [0.0, 0.0, 0.0]
        self._blk_sf = [0.0, 0.0, 0.0]
        self._blk_sf2 = [0.0, 0.0, 0.0]

    def duration_us(self, dt_us: int) -> int:
        """How long the still window lasts, at the nominal IMU period dt_us."""
        return sum(b.n for b in self.blocks) * dt_us

    def add(self, s: ImuInput, dt_us: int) -> None:
        """One sample into the current block; a full block joins the window if still, else
        the window restarts."""
        w = s.omega_flu_rad_s
        f = s.f_flu_m_s2
        if self._blk_n == 0:
            self._blk_t0 = s.t_us
        self._blk_n += 1
        for i in range(3):
            self._blk_sw[i] += w[i]
            self._blk_sw2[i] += w[i] * w[i]
            self._blk_sf[i] += f[i]
            self._blk_sf2[i] += f[i] * f[i]
        if s.t_us - self._blk_t0 + dt_us < self._block_us:
            return
        st = self.settings
        n = self._blk_n
        mw = [a / n for a in self._blk_sw]
        mf = [a / n for a in self._blk_sf]
        vw = max(self._blk_sw2[i] / n - mw[i] * mw[i] for i in range(3))
        vf = max(self._blk_sf2[i] / n - mf[i] * mf[i] for i in range(3))
        still = (vw <= (st.align_noise_factor * st.gyro_noise_rad_s) ** 2
                 and vf <= (st.align_noise_factor * st.accel_noise_m_s2) ** 2
                 and math.sqrt(mw[0] ** 2 + mw[1] ** 2 + mw[2] ** 2) <= st.align_gyro_max_rad_s
                 and abs(math.sqrt(mf[0] ** 2 + mf[1] ** 2 + mf[2] ** 2) - self._g)
                 <= 10.0 * st.align_accel_change_m_s2)
        if still and self.blocks:
            nt = sum(b.n for b in self.blocks)
            wf = [sum(b.sf[i] for b in self.blocks) / nt for i in range(3)]
            still = math.dist(wf, mf) <= st.align_accel_change_m_s2
        blk = Block(n, (self._blk_sw[0], self._blk_sw[1], self._blk_sw[2]),
                    (self._blk_sf[0], self._blk_sf[1], self._blk_sf[2]))
        if still:
            self.blocks.append(blk)
            keep = self._align_us + self._block_us
            while self.blocks and (sum(b.n for b in self.blocks) - self.blocks[0].n) \
                    * dt_us >= keep:
                self.blocks.popleft()
        else:
            self.blocks.clear()
        self._clear_block()

    def gyro_bias(self) -> tuple[Vec3, float]:
        """(the window's mean gyro, its sd: the noise over sqrt(n), floored at 1e-4 rad/s)."""
        blocks = self.blocks
        n = sum(b.n for b in blocks)
        bg = (sum(b.sw[0] for b in blocks) / n, sum(b.sw[1] for b in blocks) / n,
              sum(b.sw[2] for b in blocks) / n)
        return bg, math.hypot(self.settings.gyro_noise_rad_s / math.sqrt(n), 1e-4)
