"""The in-process engine: a whole team in one process, for sweeping many cases fast.

The world core (``simworld.world.World``) and one ``agent.controller.Controller`` per
robot, stepped in lockstep the way the bus runs them: at tick k every agent gets its
robot's sensing and pose (the simulator's truth, its dead reckoning with
``localization="odometry"``, or with ``localization="pf"`` the localizer core's
estimate from the row of scanners' scans of tick k and every robot's odometry) and its
neighbours' states of tick k-1, then the world steps with every command. It is the
run ``btrack sim`` makes with the same case, seed and pose source, bit for bit (a test
compares the tracks); only the bus's timeouts under load could make a bus run differ.
No processes, no bus, no clock: a 3-robot 1200 s case takes about a second with truth
poses.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from agent import config as agent_config
from agent.controller import Controller, Gains, Neighbour, RobotLimits, initial_segment
from agent.patrol import PatrolConfig
from agent.ring import frame_shift, initial_arc
from agent.ringcontrol import RingController
from report.measures import EdgeModel, TeamErrors, change_recovery, team_errors, team_measures
from simworld.change import changing_map, frames
from simworld.maps import GridMap, load_map
from simworld.world import ODOM_NOISE, ROBOT_RADIUS_M, Reading, World, ring_depth_bins
from wire import Scan

if TYPE_CHECKING:
    from report.ring import RingEdge

DT_S = 0.1  # the world's tick at 10 Hz control


@dataclass(frozen=True)
class EngineCase:
    """One simulated team: the same settings as ``btrack sim``'s."""

    map: str
    robots: int = 3
    start: str = "in-phase"
    duration_s: float = 1200.0
    seed: int = 1
    overrides: dict[str, dict[str, Any]] = field(default_factory=dict)
    localization: str = "truth"  # "odometry": dead reckoning; "pf": the localizer's
    odom_noise: float = ODOM_NOISE
    odom_turn_noise: float | None = None  # None: as odom_noise (the world's default)
    scale: float = 0.05  # metres per pixel of a PNG map
    config: str | None = None  # an agent configuration file (TOML), under the overrides
    scanners: int = 0  # with pf: scanners in the row, 0 for one per 10 m of edge
    change: tuple[str, ...] = ()  # --change specs: the map changes during the run


@dataclass
class Tracks:
    """Every robot's true track and what its agent published, per tick: arrays of
    shape (robots, ticks)."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    direction: np.ndarray
    phase: np.ndarray  # the phase the agent computed (eq. 3.1 from its own pose)
    workload: np.ndarray  # the workload the agent believed
    cycle_s: np.ndarray  # the team cycle the agent used
    pose_error: np.ndarray  # how far the pose the agent steered by was from the truth, m
    # On a closed edge: the true pose in edge coordinates, s in the agent's own frame
    # (the whole turn nearest its arc's middle) and d into the ice; None on an open edge
    s: np.ndarray | None = None
    d: np.ndarray | None = None
    # A map that changes: the frames of the true patrol depth the world would tell the
    # recorder (simworld.change.frames: their times, a depth per map cell each) and the
    # changes' windows, flat [t0, t1, ...]; empty for a static map
    frame_t: list[float] = field(default_factory=list)
    frames: list[list[float]] = field(default_factory=list)
    change_windows: list[float] = field(default_factory=list)


def run(case: EngineCase, gmap: GridMap | None = None) -> tuple[GridMap, Tracks]:
    """Run one case in lockstep; the map and every robot's tracks."""
    if case.localization not in ("truth", "odometry", "pf"):
        raise ValueError(f"the in-process engine takes truth, odometry or pf poses, not "
                         f"{case.localization!r}")
    gains, patrol, limits = agent_config.load(case.config, case.overrides)
    gmap = gmap or load_map(case.map, case.scale, seed=case.seed)
    if gmap.closed and case.change:
        raise ValueError("--change: a closed edge (a ring round a floe) does not change yet;"
                         " only an open edge's algae does")
    if gmap.closed:
        return gmap, _run_ring(case, gmap, gains, patrol, limits)
    change = changing_map(gmap, case.change, case.scale, case.seed)
    n = case.robots
    world = World(gmap, n, case.start, seed=case.seed, odom_noise=case.odom_noise,
                  odom_turn_noise=case.odom_turn_noise, change=change)
    odometry = case.localization == "odometry"
    lo_e, hi_e = gmap.edge_lo, gmap.edge_hi
    localizer = _Localization(gmap, n, case) if case.localization == "pf" else None
    ticks = int(round(case.duration_s / DT_S))
    arrays = [np.zeros((n, ticks)) for _ in range(9)]
    x, y, lo, hi, direction, seen_phase, seen_work, cycle, pose_error = arrays
    controllers: list[Controller] = []
    published: list[Neighbour | None] = [None] * n  # each agent's state of tick k-1
    for k in range(ticks):
        cmds, now = {}, []
        if localizer is not None:  # the world scans before it senses, as on the bus
            scans = localizer.scan(world)
        readings = [world.sense(i) for i in range(n)]
        if localizer is not None:
            poses = localizer.poses(scans, readings)
        for i in range(n):
            reading = readings[i]
            if localizer is not None:
                px, py, pth = poses[i]
            else:
                px, py, pth = world.odometry_pose(i) if odometry else world.truth(i)
            if k == 0:
                seg = initial_segment(i, n, lo_e, hi_e)
                controllers.append(Controller(i, *seg, lo_e, hi_e, px, gains, patrol, limits))
            out = controllers[i].step(
                DT_S, px, py, pth, reading.ice, reading.algae,
                published[i - 1] if i > 0 else None,
                published[i + 1] if i + 1 < n else None,
                i > 0, i + 1 < n,
            )
            now.append(controllers[i].published)  # what agent i puts on the bus
            cmds[i] = (out.v, out.omega)
            x[i, k], y[i, k] = world.truth(i)[:2]
            lo[i, k], hi[i, k], direction[i, k] = out.lo, out.hi, out.direction
            seen_phase[i, k], seen_work[i, k] = out.phase, out.workload
            cycle[i, k] = out.cycle_s
            pose_error[i, k] = np.hypot(px - x[i, k], py - y[i, k])
        published = list(now)
        world.step(cmds, DT_S)
    t = np.arange(ticks) * DT_S
    tracks = Tracks(t, x, y, lo, hi, direction, seen_phase, seen_work, cycle, pose_error)
    if change is not None:
        tracks.frame_t, tracks.frames = frames(change, ticks, DT_S, gmap.cell_m)
        tracks.change_windows = change.windows
    return gmap, tracks


def _run_ring(case: EngineCase, gmap: GridMap, gains: Gains, patrol: PatrolConfig,
              limits: RobotLimits) -> Tracks:
    """``run`` on a closed edge: a ring of ``RingController``s, every robot's
    neighbours i - 1 and i + 1 mod n, with truth poses (pf and odometry round a floe
    are later work)."""
    if case.localization != "truth":
        raise ValueError("a ring on a closed edge runs with truth poses only, so far")
    n = case.robots
    edge = gmap.closed_edge
    world = World(gmap, n, case.start, seed=case.seed, odom_noise=case.odom_noise,
                  odom_turn_noise=case.odom_turn_noise)
    ticks = int(round(case.duration_s / DT_S))
    arrays = [np.zeros((n, ticks)) for _ in range(11)]
    x, y, lo, hi, direction, seen_phase, seen_work, cycle, pose_error, s, d = arrays
    controllers = []
    for i in range(n):
        px, py, _ = world.truth(i)
        controllers.append(RingController(i, n, edge, *initial_arc(i, n, edge.length), px,
                                          py, gains, patrol, limits))
    published: list[Neighbour | None] = [None] * n
    for k in range(ticks):
        cmds, now = {}, []
        readings = [world.sense(i) for i in range(n)]
        for i in range(n):
            px, py, pth = world.truth(i)
            ctl = controllers[i]
            out = ctl.step(DT_S, px, py, pth, readings[i].ice, readings[i].algae,
                           published[(i - 1) % n], published[(i + 1) % n])
            now.append(ctl.published)
            cmds[i] = (out.v, out.omega)
            x[i, k], y[i, k] = px, py
            lo[i, k], hi[i, k], direction[i, k] = out.lo, out.hi, out.direction
            seen_phase[i, k], seen_work[i, k] = out.phase, out.workload
            cycle[i, k] = out.cycle_s
            # the true pose in the frame: the one the agent steered by (truth poses),
            # its s in the whole turn of the arc it ends the tick with
            st, d[i, k], _ = ctl.edge_coordinates
            s[i, k] = st + frame_shift(st, 0.5 * (out.lo + out.hi), edge.length)
        published = list(now)
        world.step(cmds, DT_S)
    t = np.arange(ticks) * DT_S
    return Tracks(t, x, y, lo, hi, direction, seen_phase, seen_work, cycle, pose_error, s, d)


class _Localization:
    """What ``btrack world --localization pf`` and ``btrack localizer`` do each tick:
    the row of scanners' scans of the true poses, then one filter step on them and the
    robots' odometry; the same seeds and defaults as the processes'."""

    def __init__(self, gmap: GridMap, n: int, case: EngineCase) -> None:
        from localizer.core import FilterConfig, Localizer
        from simworld.laser import RANGE_NOISE_M, laser_row

        self.lasers = laser_row(gmap.edge_lo, gmap.edge_hi, gmap.y_top, case.scanners or None,
                                RANGE_NOISE_M, case.seed, ROBOT_RADIUS_M)
        self.n = n
        self.core = Localizer(n, FilterConfig(), seed=case.seed)

    def scan(self, world: World) -> list[Scan]:
        centres = [world.truth(i)[:2] for i in range(self.n)]
        out = []
        for j, laser in enumerate(self.lasers):
            s = laser.scanner
            out.append(Scan(0.0, 0, laser.scan(centres), s.x, s.y, s.theta, s.angle_min,
                            s.angle_step, s.range_max, j, len(self.lasers)))
        return out

    def poses(self, scans: list[Scan], readings: list[Reading]
              ) -> list[tuple[float, float, float]]:
        from localizer.core import ScanGeometry

        dist = np.array([r.odom_dist_m for r in readings])
        dtheta = np.array([r.odom_dtheta for r in readings])
        estimates = self.core.step_scans(
            [(np.asarray(s.ranges), ScanGeometry.of(s)) for s in scans], dist, dtheta)
        return [(e.x, e.y, e.theta) for e in estimates]


def measures(gmap: GridMap, tracks: Tracks) -> dict[str, float]:
    """Every measure of the report (``report.measures.team_measures``) of a run: the
    map's edge and true patrol depth as the world tells the recorder, the robots' true
    tracks, and what their agents published."""
    if tracks.s is not None and tracks.d is not None:  # a ring on a closed edge
        from report.ring import ring_measures

        ring = ring_edge(gmap)
        tr = tracks
        return ring_measures(tr.t, tracks.s, tracks.d, tr.lo, tr.hi, tr.direction,
                             tr.phase, tr.workload, ring)
    tr = tracks
    return team_measures(tr.t, tr.x, tr.y, tr.lo, tr.hi, tr.direction, tr.phase,
                         tr.workload, edge_model(gmap, tracks))


def ring_edge(gmap: GridMap) -> RingEdge:
    """A closed edge as the ring's measures see it, as the world tells the recorder
    (``World.info``): its true patrol depth per bin of about a map cell round it."""
    from report.ring import RingEdge

    length = gmap.closed_edge.length
    bins = ring_depth_bins(gmap)
    return RingEdge(length, length / bins, gmap.ring_patrol_depth_bins(bins), ROBOT_RADIUS_M)


def edge_model(gmap: GridMap, tracks: Tracks) -> EdgeModel:
    """The open edge as the report sees it from the world's WorldInfo: the map's cells
    as bins, and on a map that changes the frames of its true depth."""
    cell = gmap.cell_m  # the report's bins: the map's cells, as WorldInfo's
    return EdgeModel(gmap.edge_lo, gmap.edge_hi, cell, gmap.patrol_depth_bins(cell),
                     gmap.edge_y_bins(cell), ROBOT_RADIUS_M, frame_t=tracks.frame_t,
                     frames=tracks.frames, change_windows=tracks.change_windows)


def change_measures(gmap: GridMap, tracks: Tracks) -> tuple[TeamErrors, list[dict[str, float]]]:
    """An open edge's error series and, for each change of its map, how the team
    rebalanced (``report.measures.change_recovery``), as ``btrack report`` finds them."""
    tr = tracks
    edge = edge_model(gmap, tracks)
    errors = team_errors(tr.t, tr.x, tr.y, tr.lo, tr.hi, tr.direction, tr.phase,
                         tr.workload, edge)
    return errors, change_recovery(errors, edge, tr.cycle_s)
