"""LMS 2xx scan geometry in SI units: which bearing each value of a telegram belongs to.

The LMS 2xx sweeps counter-clockwise from its right: value 0 looks along -90 degrees
from the scanner's heading (the 180 degree variant) or -50 degrees (the 100 degree one).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hwbridge.lms import codec


@dataclass(frozen=True)
class ScanGeometry:
    angle_deg: int = 180  # 100 or 180
    resolution_centideg: int = 50  # 25, 50 or 100
    range_max_m: float = 8.183  # mm mode: 13 bits of millimetres

    def __post_init__(self) -> None:
        if self.angle_deg not in (100, 180) or self.resolution_centideg not in (25, 50, 100):
            raise ValueError("variant: angle 100 or 180 degrees, resolution 25, 50 or 100")
        if self.angle_deg == 180 and self.resolution_centideg == 25:
            raise ValueError("the LMS 2xx offers 0.25 degrees only over 100 degrees")

    @property
    def beams(self) -> int:
        return codec.beam_count(self.angle_deg, self.resolution_centideg)

    @property
    def angle_min(self) -> float:
        return -math.radians(self.angle_deg / 2.0)

    @property
    def angle_step(self) -> float:
        return math.radians(self.resolution_centideg / 100.0)

    def bearings(self) -> list[float]:
        return [self.angle_min + j * self.angle_step for j in range(self.beams)]
