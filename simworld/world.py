"""The simulated world (pure): robots on a map, their sensors, odometry and stepping.

No I/O, no clock: the process shell calls ``sense``/``truth``/``odometry_pose`` for
tick k, then ``step`` with the commands and ``dt``. Odometry noise comes from a seeded
numpy Generator, so the same seed and the same commands give the same run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simworld.change import ChangingMap
from simworld.kinematics import integrate_arc, limit_wheels
from simworld.maps import MIN_DEPTH_M, ROBOT_ROOM_M, GridMap
from simworld.sensors import Slip, pose_back

ROBOT_RADIUS_M = 0.17
MARGIN_OUT_M = 0.3  # the patrol goes this far back out past the edge before turning
START_INSIDE_M = 0.05  # phase-0 robots start a hair inside their segment
AHEAD_PHASE = 2.0 * math.pi / 5.0
PARKED_BEHIND_M = 0.5  # robots not in the starting team wait this far behind the start line
ODOM_NOISE = 0.02  # odometry noise by default: std of each step's distance (and turn), fraction


@dataclass(frozen=True)
class Reading:
    """What robot i's own sensors report at the current tick."""

    ice: bool
    algae: bool
    odom_dist_m: float  # distance driven during the previous step, from odometry
    odom_dtheta: float  # heading change during the previous step, from odometry


def parse_start(start: str, n: int) -> int | None:
    """The robot started ahead for ``ahead:K``, None for ``in-phase``; ValueError else."""
    if start == "in-phase":
        return None
    if start.startswith("ahead:"):
        try:
            k = int(start.removeprefix("ahead:"))
        except ValueError:
            k = -1
        if 0 <= k < n:
            return k
        raise ValueError(f"bad start {start!r}: K in ahead:K must be a robot id 0..{n - 1}")
    raise ValueError(f"bad start {start!r}: use in-phase or ahead:K")


def start_poses(gmap: GridMap, n: int, start: str) -> list[tuple[float, float, float]]:
    """Start poses (DESIGN.md): equal initial segments of [edge_lo, edge_hi], 1 m below
    the lowest edge, heading +y; phase 0 a hair inside the segment, or phase 2 pi / 5
    (0.4 of the segment into the round trip) for the robot started ahead."""
    ahead = parse_start(start, n)
    if gmap.closed:
        return _ring_poses(gmap, n, ahead, ROBOT_ROOM_M)
    lo, hi = gmap.edge_lo, gmap.edge_hi
    seg = (hi - lo) / n
    y = -ROBOT_ROOM_M  # y = 0 is the lowest edge
    poses = []
    for i in range(n):
        s_i = lo + i * seg
        frac = AHEAD_PHASE / (2.0 * math.pi) * 2.0  # a round trip is twice the segment
        x = s_i + frac * seg if i == ahead else s_i + min(START_INSIDE_M, 0.5 * seg)
        poses.append((x, y, math.pi / 2.0))
    return poses


def _ring_poses(gmap: GridMap, n: int, ahead: int | None, out_m: float
                ) -> list[tuple[float, float, float]]:
    """Start poses round a closed edge: ``out_m`` out along the outward normal of equal
    arcs from s = 0, heading in along the normal; phase 0 a hair inside the arc, the
    robot started ahead 0.4 of its round trip in."""
    edge = gmap.closed_edge
    seg = edge.length / n
    poses = []
    for i in range(n):
        frac = AHEAD_PHASE / (2.0 * math.pi) * 2.0
        s = i * seg + (frac * seg if i == ahead else min(START_INSIDE_M, 0.5 * seg))
        x, y = edge.at(s, -out_m)
        poses.append((x, y, edge.tangent_angle(s) + math.pi / 2.0))
    return poses


def parked_poses(gmap: GridMap, count: int) -> list[tuple[float, float, float]]:
    """Robots that join the team later wait behind the start line (between it and the
    laser), spread evenly along the edge, heading +y (in along the normal on a closed
    edge)."""
    if gmap.closed:
        return _ring_poses(gmap, count, None, ROBOT_ROOM_M + PARKED_BEHIND_M)
    lo, hi = gmap.edge_lo, gmap.edge_hi
    y = -ROBOT_ROOM_M - PARKED_BEHIND_M
    return [(lo + (j + 0.5) * (hi - lo) / count, y, math.pi / 2.0) for j in range(count)]


class World:
    """n differential-drive robots on a ``GridMap``: the first ``team`` (default all)
    start on the start line in equal segments, the rest are parked behind it until an
    agent drives them. With ``change`` (a ``ChangingMap`` of ``gmap``) the algae the
    robots sense is that map's at the world's time."""

    def __init__(
        self,
        gmap: GridMap,
        n: int,
        start: str = "in-phase",
        seed: int = 1,
        odom_noise: float = ODOM_NOISE,
        team: int | None = None,
        odom_turn_noise: float | None = None,
        slip: Slip | None = None,
        change: ChangingMap | None = None,
    ) -> None:
        team = n if team is None else team
        if not 1 <= team <= n:
            raise ValueError("need at least one robot, and a starting team of 1 to n")
        turn_noise = odom_noise if odom_turn_noise is None else odom_turn_noise
        if odom_noise < 0 or turn_noise < 0:
            raise ValueError("odometry noise must be >= 0")
        self.map = gmap
        self.n = n
        self.start = start
        self.odom_noise = odom_noise  # std of the distance, as a fraction of it
        self.odom_turn_noise = turn_noise  # std of the turn, as a fraction of it
        self._rng = np.random.default_rng(seed)
        poses = start_poses(gmap, team, start) + (parked_poses(gmap, n - team) if n > team else [])
        self._x = [p[0] for p in poses]
        self._y = [p[1] for p in poses]
        self._th = [p[2] for p in poses]
        self._ox, self._oy, self._oth = list(self._x), list(self._y), list(self._th)
        self._odom_d = [0.0] * n
        self._odom_dth = [0.0] * n
        # each robot's true motion over the last step (distance, turn): where it was
        # during the step, for a sensor that reads late or a laser that sweeps
        self.motion = [(0.0, 0.0)] * n
        self.slip = slip  # None: the wheels never slip (the ideal world)
        self.t = 0.0
        self.k = 0
        if change is not None and change.base is not gmap:
            raise ValueError("the changing map must be a change of the world's map")
        self.change = change
        self._extent: np.ndarray | None = None  # the changing map's algae now, if changed
        self._changed_to(self.t)

    def _changed_to(self, t: float) -> None:
        """The map at time ``t``: the changed algae's extents once a change began."""
        c = self.change
        self._extent = c.extent_cells(t) if c is not None and c.started(t) else None

    def truth(self, i: int) -> tuple[float, float, float]:
        return self._x[i], self._y[i], self._th[i]

    def odometry_pose(self, i: int) -> tuple[float, float, float]:
        """Dead-reckoned pose from the noisy odometry, from the true start pose."""
        return self._ox[i], self._oy[i], self._oth[i]

    def truth_back(self, i: int, back_s: float, dt: float) -> tuple[float, float, float]:
        """Where robot i was ``back_s`` (at most ``dt``) seconds before now, along its
        last step of ``dt``."""
        return pose_back(self.truth(i), self.motion[i], dt, back_s)

    def move(self, i: int, dx: float, dy: float) -> None:
        """Carry robot i by (dx, dy) without its odometry noticing (a kidnapping)."""
        self._x[i] += dx
        self._y[i] += dy

    def sense(self, i: int) -> Reading:
        x, y = self._x[i], self._y[i]
        return Reading(
            ice=self.map.ice_at(x, y),
            algae=(self.map.algae_at(x, y) if self._extent is None or self.change is None
                   else self.change.algae_at(x, y, self._extent)),
            odom_dist_m=self._odom_d[i],
            odom_dtheta=self._odom_dth[i],
        )

    def step(self, cmds: dict[int, tuple[float, float]], dt: float) -> None:
        """Drive every robot for ``dt`` at its command (zero if it has none)."""
        noise, turn_noise = self.odom_noise, self.odom_turn_noise
        draws = self._rng.standard_normal(2 * self.n).tolist()
        slips = self.slip.draw(self.n).tolist() if self.slip is not None else None
        for i in range(self.n):
            v, omega = cmds.get(i, (0.0, 0.0))
            v, omega = limit_wheels(v, omega)
            dist, dtheta = v * dt, omega * dt  # what the wheels turned
            if slips is None:
                moved, turned = dist, dtheta
            else:  # the robot makes a little less than its wheels
                moved, turned = dist * (1.0 - slips[i][0]), dtheta * (1.0 - slips[i][1])
            self._x[i], self._y[i], self._th[i] = integrate_arc(
                self._x[i], self._y[i], self._th[i], moved, turned
            )
            self.motion[i] = (moved, turned)
            odist = dist + noise * abs(dist) * draws[2 * i]
            odth = dtheta + turn_noise * abs(dtheta) * draws[2 * i + 1]
            self._odom_d[i], self._odom_dth[i] = odist, odth
            self._ox[i], self._oy[i], self._oth[i] = integrate_arc(
                self._ox[i], self._oy[i], self._oth[i], odist, odth
            )
        self.k += 1
        self.t = self.k * dt
        if self.change is not None:
            self._changed_to(self.t)

    def info(self, bin_m: float | None = None) -> dict[str, object]:
        """The world's part of wire.WorldInfo (edge, depths, geometry). The true depths
        and edge come per bin of ``bin_m``, by default the map's own cell, so the
        report's true workload is the map's, not a binned copy of it (a step of the
        algae inside a 0.1 m bin would otherwise move with the bin's side)."""
        if self.map.closed:
            return self._ring_info()
        bin_m = self.map.cell_m if bin_m is None else bin_m
        change = self.change
        if change is not None:  # the depth in force from now, and when the map changes
            moving: dict[str, object] = {
                "patrol_depth": change.patrol_depth_bins(self.t, bin_m), "depth_t": self.t,
                "change": change.spec, "change_windows": change.windows}
        else:
            moving = {"patrol_depth": self.map.patrol_depth_bins(bin_m)}
        return {
            "edge_lo": self.map.edge_lo,
            "edge_hi": self.map.edge_hi,
            "bin_m": bin_m,
            **moving,
            "edge_y": self.map.edge_y_bins(bin_m),
            "robot_radius": ROBOT_RADIUS_M,
            "min_depth": MIN_DEPTH_M,
            "margin_out": MARGIN_OUT_M,
            "odom_noise": self.odom_noise,
            "odom_turn_noise": self.odom_turn_noise,
        }

    def _ring_info(self) -> dict[str, object]:
        """``info`` on a closed edge: its contour, and the true patrol depth per bin of a
        whole number of bins about a map cell long round it from s = 0 (as
        ``deploy.engine.measures`` bins it)."""
        edge = self.map.closed_edge
        bins = ring_depth_bins(self.map)
        return {
            "edge_lo": 0.0,
            "edge_hi": edge.length,
            "bin_m": edge.length / bins,
            "patrol_depth": self.map.ring_patrol_depth_bins(bins),
            "robot_radius": ROBOT_RADIUS_M,
            "min_depth": MIN_DEPTH_M,
            "margin_out": MARGIN_OUT_M,
            "odom_noise": self.odom_noise,
            "odom_turn_noise": self.odom_turn_noise,
            "closed": True,
            "contour": [v for point in edge.points for v in point],
        }


def ring_depth_bins(gmap: GridMap) -> int:
    """How many bins the true patrol depth of a closed edge comes in: a whole number, each
    about one map cell long."""
    return max(1, round(gmap.closed_edge.length / gmap.cell_m))


__all__ = ["ROBOT_RADIUS_M", "Reading", "World", "parse_start", "start_poses"]
