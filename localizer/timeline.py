"""The odometry between the filter's time and now, for scans that come when the laser
sends them (a real LMS), not on the control tick.

A robot's sensing of tick k carries its odometry over the period ((k-1) dt, k dt].
The filter stands at the time of the last scan it took in. A scan measured at t_s
(its sweep's middle; it arrives a telegram's transmission later, 0.2 s at 38400 baud,
two ticks) first needs the particles moved from the filter's time to t_s: the whole
periods between, and the share of the period t_s falls in, split in proportion to
time (a robot's speed is steady over 0.1 s). The rest of that period stays for the
next scan. Meanwhile every tick's pose is the filter's estimate carried forward by the
odometry since its time (``advance``), so the agents get a pose on every tick, late
scans or none.

Pure: no clock, no I/O. Times are in ticks (t / dt) so that a scan on the tick itself
takes its period whole, to the bit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

WHOLE = 1e-6  # ticks: a time this close to a tick is the tick (0.1 us at 10 Hz)


class OdometryTimeline:
    """Every robot's odometry per tick period from the filter's time on.

    ``at`` is the filter's time in ticks (a scan at 12.4 dt leaves it at 12.4); period
    k is (k - 1, k]. Odometry of a period wholly behind the filter is refused (``add``
    returns False): the filter passed it taking its motion as none."""

    def __init__(self, robots: int, at: float = 0.0) -> None:
        self.robots = robots
        self.at = at
        # tick k -> (dist, dtheta) per robot of the period ((k-1) dt, k dt], NaN unknown
        self.periods: dict[int, np.ndarray] = {}

    def add(self, k: int, robot: int, dist: float, dtheta: float) -> bool:
        """Robot ``robot``'s odometry of tick k; False if the filter is past it."""
        if k <= self.at + WHOLE:
            return False
        row = self.periods.get(k)
        if row is None:
            row = self.periods[k] = np.full((self.robots, 2), np.nan)
        row[robot] = (dist, dtheta)
        return True

    def _pieces(self, until: float) -> list[tuple[int, float]]:
        """(tick, share of its period) from the filter's time to ``until``."""
        out: list[tuple[int, float]] = []
        t = self.at
        while t < until - WHOLE:
            k = math.floor(t + WHOLE) + 1  # the period t starts in
            end = min(float(k), until)
            share = end - t
            out.append((k, 1.0 if share >= 1.0 - WHOLE else share))
            t = end
        return out

    def complete(self, until: float) -> bool:
        """Whether every robot's odometry is in for every period up to ``until``."""
        return all(k in self.periods and not np.isnan(self.periods[k]).any()
                   for k, _ in self._pieces(until))

    def _motion(self, k: int, share: float) -> np.ndarray:
        row = self.periods.get(k)
        row = np.zeros((self.robots, 2)) if row is None else np.nan_to_num(row, nan=0.0)
        return row if share == 1.0 else share * row

    def take(self, until: float) -> tuple[np.ndarray, np.ndarray]:
        """Each robot's motion from the filter's time to ``until`` (ticks), summed over
        the periods between (the share of the one ``until`` falls in); the filter's time
        becomes ``until``. Odometry not in counts as none."""
        until = snap(until)
        total = np.zeros((self.robots, 2))
        for k, share in self._pieces(until):
            total = total + self._motion(k, share)
        for k in [k for k in self.periods if k <= until + WHOLE]:
            del self.periods[k]
        self.at = max(self.at, until)
        return total[:, 0], total[:, 1]

    def ahead(self, until: float) -> list[np.ndarray]:
        """The motions, period by period ((robots, 2) each), from the filter's time to
        ``until``, not taken."""
        return [self._motion(k, share) for k, share in self._pieces(snap(until))]


def snap(ticks: float) -> float:
    """A time in ticks, the tick itself when it is within WHOLE of one."""
    r = round(ticks)
    return float(r) if abs(ticks - r) < WHOLE else ticks


def advance(x: float, y: float, theta: float, motions: Sequence[tuple[float, float]]
            ) -> tuple[float, float, float]:
    """A pose carried along each (distance, turn) in turn, each an arc at its mid
    heading (the motion model's mean)."""
    for dist, dtheta in motions:
        mid = theta + 0.5 * dtheta
        x, y, theta = x + dist * math.cos(mid), y + dist * math.sin(mid), theta + dtheta
    return x, y, theta

