"""One robot's whole control law per tick: workload balance on its two boundaries,
phase balance on its desired phase, the patrol's steering and the speed law.
Pure: time, pose, sensing and the neighbours' last published states come in as
arguments; a command and the state to publish come out."""

from __future__ import annotations

import math
from dataclasses import dataclass

from agent.partition import SegmentView, shared_boundary
from agent.patrol import DepthMap, Motion, Patrol, PatrolConfig
from agent.phase import (
    TWO_PI,
    boundary_phase_shift,
    consensus_term,
    desired_phase_step,
    limit_lead,
    pass_speed,
    position_to_phase,
    wrap_pi,
)

SHARED_REACH_M = 0.3  # a robot tells its neighbours its depths this close to its ends
HURRY_RAD = 0.4  # a robot this far behind its desired phase measures nothing slowly


@dataclass(frozen=True)
class Gains:
    k_s: float = 0.01  # boundary step per m^2 of workload error per tick (eq. 4.3)
    k_phi: float = 0.3  # phase consensus gain per tick (eq. 4.7); < 1/2 is stable for any n
    cycle_s: float = 200.0  # period of the common cycle: phi_dot_des = 2 pi / cycle_s
    max_lead_rad: float = 1.0  # the desired phase stays this close to the actual one
    min_segment_m: float = 0.3

    def __post_init__(self) -> None:
        if self.k_s <= 0 or self.k_phi <= 0:
            raise ValueError("gains must be positive")
        if self.cycle_s <= 0 or self.max_lead_rad <= 0 or self.min_segment_m <= 0:
            raise ValueError("cycle_s, max_lead_rad and min_segment_m must be positive")

    @property
    def phase_rate(self) -> float:
        return TWO_PI / self.cycle_s


@dataclass(frozen=True)
class RobotLimits:
    v_max: float = 0.5  # m/s, per wheel as well
    wheel_base_m: float = 0.26


@dataclass(frozen=True)
class Neighbour:
    """A neighbour's state as it published it at the previous tick."""

    robot: int
    lo: float
    hi: float
    phase_des: float
    workload: float
    turns: float = 0.0  # its desired phase unwrapped, rad: the team's sweep count
    depths: tuple[tuple[int, float], ...] = ()  # (bin, depth) it measured near its ends


@dataclass(frozen=True)
class Output:
    v: float
    omega: float
    lo: float
    hi: float
    phase: float
    phase_des: float
    workload: float
    depth_avg: float
    direction: int
    motion: Motion
    turns: float = 0.0  # phi_des unwrapped, rad
    end_depths: tuple[tuple[int, float], ...] = ()  # its depths near its ends


def wheel_limited(v: float, omega: float, limits: RobotLimits) -> tuple[float, float]:
    """Scale v and omega together so neither wheel exceeds v_max (curvature kept)."""
    half = 0.5 * limits.wheel_base_m * abs(omega)
    fastest = abs(v) + half
    if fastest <= limits.v_max or fastest == 0.0:
        return v, omega
    scale = limits.v_max / fastest
    return v * scale, omega * scale


class Controller:
    """The control core of robot ``robot``."""

    def __init__(
        self,
        robot: int,
        lo: float,
        hi: float,
        edge_lo: float,
        edge_hi: float,
        x: float,
        gains: Gains | None = None,
        patrol: PatrolConfig | None = None,
        limits: RobotLimits | None = None,
    ):
        if not edge_lo <= lo < hi <= edge_hi:
            raise ValueError(f"segment [{lo}, {hi}] not inside the edge [{edge_lo}, {edge_hi}]")
        self.robot = robot
        self.gains = gains or Gains()
        self.limits = limits or RobotLimits()
        cfg = patrol or PatrolConfig()
        self.edge = (edge_lo, edge_hi)
        self.lo, self.hi = lo, hi
        self.depth_map = DepthMap(edge_lo, cfg.bin_m, cfg.min_depth_m)
        self.patrol = Patrol(cfg, self.depth_map, x, direction=1)
        self.phase_des: float | None = None
        self.turns = 0.0  # phi_des unwrapped: the count of sweeps the pass grid walks by
        self.published: Neighbour | None = None  # what we told the neighbours last tick

    def _update_boundaries(self, lower: Neighbour | None, upper: Neighbour | None,
                           has_lower: bool, has_upper: bool) -> None:
        g = self.gains
        me = self.published
        if not has_lower:
            self.lo = self.edge[0]
        elif lower is not None and me is not None:
            self.lo = shared_boundary(
                SegmentView(lower.lo, lower.hi, lower.workload),
                SegmentView(me.lo, me.hi, me.workload),
                g.k_s, g.min_segment_m,
            )
        if not has_upper:
            self.hi = self.edge[1]
        elif upper is not None and me is not None:
            self.hi = shared_boundary(
                SegmentView(me.lo, me.hi, me.workload),
                SegmentView(upper.lo, upper.hi, upper.workload),
                g.k_s, g.min_segment_m,
            )
        if self.hi - self.lo < 1e-6:  # never publish an empty segment
            mid = 0.5 * (self.lo + self.hi)
            self.lo, self.hi = mid - 0.5e-6, mid + 0.5e-6

    def step(
        self,
        dt: float,
        x: float,
        y: float,
        theta: float,
        ice: bool,
        algae: bool,
        lower: Neighbour | None,
        upper: Neighbour | None,
        has_lower: bool,
        has_upper: bool,
    ) -> Output:
        """One control tick. ``has_lower``/``has_upper``: whether a live neighbour
        exists on that side (from membership); ``lower``/``upper``: its state of the
        previous tick, or None if not heard yet."""
        g = self.gains
        old = (self.lo, self.hi)
        for nb in (lower, upper):
            if nb is not None:
                self.depth_map.learn(nb.depths)
        self._update_boundaries(lower, upper, has_lower, has_upper)
        before = self.phase_des
        if before is not None and self.published is not None:
            lag = wrap_pi(before - position_to_phase(x, self.lo, self.hi, self.patrol.direction))
            self.patrol.hurry = lag > HURRY_RAD
        steer = self.patrol.step(x, y, theta, ice, algae, self.lo, self.hi)
        direction = self.patrol.direction
        phase = position_to_phase(x, self.lo, self.hi, direction)
        if self.phase_des is None:
            self.phase_des = phase
        else:
            shift = boundary_phase_shift(x, direction, old, (self.lo, self.hi))
            mine = self.published.phase_des if self.published else self.phase_des
            consensus = consensus_term(
                mine,
                lower.phase_des if (has_lower and lower) else None,
                upper.phase_des if (has_upper and upper) else None,
                g.k_phi,
            )
            self.phase_des = desired_phase_step(mine, g.phase_rate, dt, shift, consensus)
        self.phase_des = limit_lead(self.phase_des, phase, g.max_lead_rad)
        self._count_turns(before, lower if has_lower else None)
        on_leg = steer.motion in (Motion.ENTER, Motion.UNDER, Motion.EXIT)
        p = self.patrol
        v = pass_speed(
            self.phase_des, phase,
            position_to_phase(p.arc_from_x, self.lo, self.hi, p.direction),
            position_to_phase(p.line_x, self.lo, self.hi, p.direction),
            on_leg, steer.measuring, p.turned > 0.05, self.limits.v_max,
            p.config.measure_speed,
        )
        v, omega = wheel_limited(v, v * steer.curvature, self.limits)
        depth_avg = self.depth_map.average(self.lo, self.hi)
        workload = depth_avg * (self.hi - self.lo)
        ends = self.depth_map.near_ends(self.lo, self.hi, SHARED_REACH_M)
        self.published = Neighbour(self.robot, self.lo, self.hi, self.phase_des, workload,
                                   self.turns, ends)
        return Output(
            v, omega, self.lo, self.hi, phase, self.phase_des, workload, depth_avg,
            direction, steer.motion, self.turns, ends,
        )

    def _count_turns(self, before: float | None, lower: Neighbour | None) -> None:
        """Unwrap the desired phase into the sweep clock the pass grid walks by. A
        robot takes its lower neighbour's count (the chain agrees from its lowest live
        robot up, a robot restarted in a running team included) and counts on its own
        without one."""
        assert self.phase_des is not None
        if lower is not None:
            self.turns = lower.turns + wrap_pi(self.phase_des - lower.phase_des)
        elif before is None:
            self.turns = self.phase_des
        else:
            self.turns += wrap_pi(self.phase_des - before)
        self.patrol.clock = self.turns / math.pi


def initial_segment(robot: int, team: int, edge_lo: float, edge_hi: float) -> tuple[float, float]:
    """Robot ``robot``'s share of equal initial segments of a team of ``team``."""
    if not 0 <= robot < team:
        raise ValueError(f"robot id {robot} outside a team of {team}")
    width = (edge_hi - edge_lo) / team
    return edge_lo + robot * width, edge_lo + (robot + 1) * width if robot + 1 < team else edge_hi


def is_finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)
