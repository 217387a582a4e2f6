"""The simulated laser range finder (pure): what a SICK LMS 2xx behind the team sees.

361 beams over 180 degrees in 0.5 degree steps, 8 m range (thesis 6.1.5). The
robots are circles (radius 0.17 m) that hide each other and whatever is behind
them; optional walls are line segments. Each return gets Gaussian range noise
(1 cm by default) and is rounded to the millimetre the LMS reports; a beam that
hits nothing within range reads the maximum range. The noise comes from a seeded
numpy Generator of its own, so turning the laser on never changes the odometry
noise of a run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from wire.messages import MAX_SCANNERS

LMS_BEAMS = 361
LMS_ANGLE_MIN = -0.5 * math.pi
LMS_ANGLE_STEP = math.pi / 360.0
LMS_RANGE_MAX_M = 8.0
RANGE_NOISE_M = 0.01
# Edge one scanner watches: 2 m behind the robots' start line, a robot 5 m to its side
# and up to 3 m deep is still 6 m away, inside the LMS's 8 m with room for the far side
# of the robot and a deeper patrol.
SCANNER_SPAN_M = 10.0


@dataclass(frozen=True)
class Scanner:
    """Where the scanner stands and how it scans. ``theta`` is the direction of its
    middle beam (angle 0); beams run from ``angle_min`` counter-clockwise."""

    x: float
    y: float
    theta: float = 0.5 * math.pi
    beams: int = LMS_BEAMS
    angle_min: float = LMS_ANGLE_MIN
    angle_step: float = LMS_ANGLE_STEP
    range_max: float = LMS_RANGE_MAX_M

    def angles(self) -> np.ndarray:
        """Beam angles relative to the scanner's heading."""
        return self.angle_min + self.angle_step * np.arange(self.beams)


@dataclass
class Laser:
    """Simulated scans of circular robots and optional walls from one ``Scanner``."""

    scanner: Scanner
    radius: float = 0.17
    noise_m: float = RANGE_NOISE_M
    walls: Sequence[tuple[float, float, float, float]] = ()  # (x0, y0, x1, y1) segments
    seed: int = 1
    stream: int = 0  # which scanner of a row: each has noise of its own
    _rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.noise_m < 0 or self.radius <= 0:
            raise ValueError("laser noise must be >= 0 and the robot radius positive")
        # the first scanner's stream is the one a single scanner always had
        key = [self.seed, 0x1A5E] if self.stream == 0 else [self.seed, 0x1A5E, self.stream]
        self._rng = np.random.default_rng(key)
        s = self.scanner
        world = s.theta + s.angles()
        self._dirs = np.stack([np.cos(world), np.sin(world)], axis=1)  # (beams, 2)

    def exact(self, centres: npt.ArrayLike) -> np.ndarray:
        """Noise-free ranges to the nearest robot or wall along every beam
        (``range_max`` where nothing is hit within range)."""
        s = self.scanner
        u = self._dirs
        out = np.full(s.beams, s.range_max)
        c = np.asarray(centres, dtype=float).reshape(-1, 2) - (s.x, s.y)
        if c.size:
            along = u @ c.T  # (beams, robots): distance to the closest approach
            miss2 = (c * c).sum(axis=1)[None, :] - along * along
            inside = self.radius**2 - miss2
            hit = (inside >= 0.0) & (along > 0.0)
            t = np.where(hit, along - np.sqrt(np.maximum(inside, 0.0)), np.inf)
            t = np.where(t >= 0.0, t, np.inf)  # the scanner inside a robot sees nothing
            out = np.minimum(out, t.min(axis=1))
        for x0, y0, x1, y1 in self.walls:
            out = np.minimum(out, self._segment(x0 - s.x, y0 - s.y, x1 - x0, y1 - y0))
        return out

    def _segment(self, px: float, py: float, ex: float, ey: float) -> np.ndarray:
        """Range along every beam to the segment p + s e, s in [0, 1] (inf if missed)."""
        return ray_segment(self._dirs[:, 0], self._dirs[:, 1], px, py, ex, ey)

    def scan(self, centres: npt.ArrayLike) -> list[float]:
        """One noisy scan: ranges in metres, millimetre resolution, misses at max."""
        s = self.scanner
        exact = self.exact(centres)
        noise = self._rng.standard_normal(s.beams) * self.noise_m
        hit = exact < s.range_max
        ranges = np.where(hit, np.clip(exact + noise, 0.0, s.range_max), s.range_max)
        return np.round(ranges, 3).tolist()


Segment = tuple[float, float, float, float]


def ray_segment(ux: np.ndarray, uy: np.ndarray, px: float, py: float, ex: float, ey: float
                ) -> np.ndarray:
    """Range along rays (ux, uy) from the origin to the segment p + s e, s in [0, 1] (inf
    where a ray misses it or runs parallel to it)."""
    den = ux * ey - uy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (px * ey - py * ex) / den
        s = (px * uy - py * ux) / den
    ok = (np.abs(den) > 1e-12) & (t > 0.0) & (s >= 0.0) & (s <= 1.0)
    return np.where(ok, t, np.inf)


def scanner_count(edge_lo: float, edge_hi: float) -> int:
    """Scanners a row behind the team needs: one per SCANNER_SPAN_M of edge."""
    return max(1, math.ceil((edge_hi - edge_lo) / SCANNER_SPAN_M - 1e-9))


def scanner_row(edge_lo: float, edge_hi: float, y: float, count: int | None = None
                ) -> list[Scanner]:
    """``count`` scanners (default ``scanner_count``) at ``y``, facing the edge, each in
    the middle of its equal share of [edge_lo, edge_hi]: one scanner is where the
    thesis's was, behind the middle of the edge."""
    count = scanner_count(edge_lo, edge_hi) if count is None else count
    if not 1 <= count <= MAX_SCANNERS:
        raise ValueError(f"scanners: 1 to {MAX_SCANNERS}, not {count}")
    if count == 1:
        return [Scanner(0.5 * (edge_lo + edge_hi), y)]
    share = (edge_hi - edge_lo) / count
    return [Scanner(edge_lo + (j + 0.5) * share, y) for j in range(count)]


def box_walls(x0: float, y0: float, x1: float, y1: float) -> list[Segment]:
    """The four walls of the rectangle [x0, x1] x [y0, y1]."""
    return [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]


def laser_row(edge_lo: float, edge_hi: float, y_top: float, count: int | None,
              noise_m: float, seed: int, radius: float, walls: bool = False) -> list[Laser]:
    """The simulated row of scanners behind a team (``scanner_row``, ``count`` of them
    or one per 10 m of edge) 1 m behind the start line, each with its own noise stream;
    ``walls`` boxes the scene 1 m beyond the edge's ends. The world's, and the
    in-process engine's."""
    from simworld.maps import LASER_ROOM_M, ROBOT_ROOM_M

    y = -(ROBOT_ROOM_M + LASER_ROOM_M)
    box = box_walls(edge_lo - 1.0, y - 0.5, edge_hi + 1.0, y_top) if walls else []
    return [Laser(s, radius, noise_m, box, seed, stream=j)
            for j, s in enumerate(scanner_row(edge_lo, edge_hi, y, count))]
