"""One robot's whole control law per tick: workload balance on its two boundaries,
phase balance on its desired phase, the patrol's steering and the speed law.
Pure: time, pose, sensing and the neighbours' last published states come in as
arguments; a command and the state to publish come out."""

from __future__ import annotations

import math
from dataclasses import dataclass

from agent.depthmap import DepthMap
from agent.partition import SegmentView, shared_boundary
from agent.patrol import IN_LEG, Motion, Patrol, PatrolConfig, Steer, TeamInput
from agent.phase import (
    TWO_PI,
    arc_may_begin,
    boundary_phase_shift,
    consensus_term,
    desired_phase_step,
    leg_speed,
    limit_lead,
    position_to_phase,
    wrap_pi,
)
from agent.plausible import edge_bins
from agent.ring import ring_bins
from agent.team import TeamRate, chain_max, cycle_for, passes_for, team_max


@dataclass(frozen=True)
class Gains:
    # Boundary step per m^2 of workload error per tick (eq. 4.3). The thesis's 0.01 took
    # a chain of 20 robots past twenty minutes to balance (the slowest mode of a chain
    # falls as 1/n^2); 0.1 is still under 2 / (4 d_max) = 0.25 for depths to 2 m.
    k_s: float = 0.1
    k_phi: float = 0.3  # phase consensus gain per tick (eq. 4.7); < 1/2 is stable for any n
    # The common cycle, phi_dot_des = 2 pi / cycle: 0 derives it from the team's need
    # (agent.team); a positive value fixes it, in seconds.
    cycle_s: float = 0.0
    cycle_margin: float = 1.15  # the cycle gives the slowest robot this much slack
    max_lead_rad: float = 1.0  # the desired phase stays this close to the actual one
    # No segment shorter: a deep bloom shared by many robots needs segments of 0.2 m
    # and less for equal work (16 passes 1 cm apart are still a patrol).
    min_segment_m: float = 0.15
    # A robot tells its neighbours its depths this close to its ends: at least
    # shared_reach_m, and shared_reach_fraction of its segment, as far as a boundary can
    # move into it before the neighbour would measure those columns itself.
    shared_reach_m: float = 0.3
    shared_reach_fraction: float = 0.5
    hurry_rad: float = 0.4  # a robot this far behind its desired phase measures nothing slowly
    ahead_wait_rad: float = 0.5  # a robot this far ahead of its desired phase waits on its leg

    def __post_init__(self) -> None:
        if self.k_s <= 0 or self.k_phi <= 0:
            raise ValueError("gains must be positive")
        if min(self.shared_reach_m, self.shared_reach_fraction, self.hurry_rad,
               self.ahead_wait_rad) <= 0:
            raise ValueError("shared_reach_m, shared_reach_fraction, hurry_rad and "
                             "ahead_wait_rad must be positive")
        if self.cycle_s < 0 or self.max_lead_rad <= 0 or self.min_segment_m <= 0:
            raise ValueError("cycle_s must be >= 0, max_lead_rad and min_segment_m positive")
        if not self.cycle_margin >= 1.0:
            raise ValueError("cycle_margin must be at least 1 (the slowest robot's need)")


@dataclass(frozen=True)
class RobotLimits:
    v_max: float = 0.5  # m/s, per wheel as well
    wheel_base_m: float = 0.26

    def __post_init__(self) -> None:
        if not (math.isfinite(self.v_max) and self.v_max > 0):
            raise ValueError(f"v_max must be a positive speed, not {self.v_max:g} m/s")
        if not (math.isfinite(self.wheel_base_m) and self.wheel_base_m > 0):
            raise ValueError(f"wheel_base_m must be positive, not {self.wheel_base_m:g} m")


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
    # The team's decision as it took it (agent.team): 0 for not known
    cycle_s: float = 0.0
    passes: int = 0
    # The chain maxima of each robot's pass need (s) and segment length (m): over the
    # robots at or below it, and at or above it; 0 for not known
    need_below: float = 0.0
    need_above: float = 0.0
    span_below: float = 0.0
    span_above: float = 0.0


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
    cycle_s: float = 0.0  # the team cycle it follows
    passes: int = 0  # the team's passes per sweep


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
        ring_length: float | None = None,
    ):
        """``ring_length``: the edge is closed, this long (agent.ringcontrol); the depth
        map's bins then run from s = 0 and a whole number of them make the ring."""
        if ring_length is None and not edge_lo <= lo < hi <= edge_hi:
            raise ValueError(f"segment [{lo}, {hi}] not inside the edge [{edge_lo}, {edge_hi}]")
        if ring_length is not None and not 0.0 < hi - lo <= ring_length:
            raise ValueError(f"arc [{lo}, {hi}] is not part of a ring of {ring_length} m")
        self.robot = robot
        self.gains = gains or Gains()
        self.limits = limits or RobotLimits()
        cfg = patrol or PatrolConfig()
        self.edge = (edge_lo, edge_hi)
        self.lo, self.hi = lo, hi
        if ring_length is None:  # its bins as the listeners of its states count them
            self.depth_map = DepthMap(edge_lo, cfg.bin_m, cfg.min_depth_m,
                                      bins=edge_bins(edge_lo, edge_hi, cfg.bin_m), edge_hi=edge_hi,
                                      refined=cfg.refined_measuring)
        else:
            self.depth_map = DepthMap(0.0, ring_bins(ring_length, cfg.bin_m), cfg.min_depth_m,
                                      refined=cfg.refined_measuring)
        self.patrol = Patrol(cfg, self.depth_map, x, direction=1)
        self.phase_des: float | None = None
        self.turns = 0.0  # phi_des unwrapped: the count of sweeps the pass grid walks by
        self.published: Neighbour | None = None  # what we told the neighbours last tick
        self.rate = TeamRate()  # the cycle, when this robot is the chain's root
        self.passes: int | None = None  # the team's passes per sweep, when known
        self.cycle_s = self.gains.cycle_s
        # What the patrol is told (agent.patrol.TeamInput): the sweep clock (turns / pi)
        # as of the last tick, and whether the robot is well behind its desired phase,
        # so measures nothing slowly.
        self.clock: float | None = None
        self.hurry = False

    def _agree(self, dt: float, lower: Neighbour | None, upper: Neighbour | None,
               has_lower: bool, has_upper: bool) -> tuple[float, int, tuple[float, ...]]:
        """The team's cycle and passes per sweep (agent.team), and this robot's chain
        maxima to publish. The root decides from the chain's maxima; every other robot
        takes its lower neighbour's decision."""
        g, cfg, lim = self.gains, self.patrol.config, self.limits
        need = self.patrol.pass_need_s(self.lo, self.hi, lim.v_max, lim.wheel_base_m)
        span = self.hi - self.lo
        lo_nb = lower if has_lower else None
        up_nb = upper if has_upper else None

        def known(value: float) -> float | None:  # 0 on the wire: not known yet
            return value if value > 0 else None

        lower_need = known(lo_nb.need_below) if lo_nb else None
        upper_need = known(up_nb.need_above) if up_nb else None
        lower_span = known(lo_nb.span_below) if lo_nb else None
        upper_span = known(up_nb.span_above) if up_nb else None
        needs = chain_max(need, lower_need, upper_need)
        spans = chain_max(span, lower_span, upper_span)
        if lo_nb is not None and lo_nb.passes > 0 and lo_nb.cycle_s > 0:
            passes, cycle = lo_nb.passes, lo_nb.cycle_s
            self.rate.cycle_s = cycle  # were it to become the root, it goes on from here
        else:
            passes = passes_for(team_max(span, lower_span, upper_span), cfg.max_spacing_m,
                                cfg.passes_per_sweep, self.passes)
            target = cycle_for(team_max(need, lower_need, upper_need), passes, g.cycle_margin)
            cycle = g.cycle_s if g.cycle_s > 0 else self.rate.update(target, dt)
        return cycle, passes, (needs.below, needs.above, spans.below, spans.above)

    def _learn(self, nb: Neighbour) -> None:
        """Take the depths a neighbour measured near the ends it shares with us."""
        self.depth_map.learn(nb.depths)

    def _chain_sides(self, lower: Neighbour | None, upper: Neighbour | None,
                     has_lower: bool, has_upper: bool) -> tuple[bool, bool]:
        """Which neighbours the team's agreement (``_agree``, ``_count_turns``) runs
        through: on a chain, both that exist."""
        return has_lower, has_upper

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
                self._learn(nb)
        self._update_boundaries(lower, upper, has_lower, has_upper)
        agree_lower, agree_upper = self._chain_sides(lower, upper, has_lower, has_upper)
        before = self.phase_des
        if before is not None and self.published is not None:
            lag = wrap_pi(before - position_to_phase(x, self.lo, self.hi,
                                                     self.patrol.view.direction))
            self.hurry = lag > self.gains.hurry_rad
        self.cycle_s, self.passes, chain = self._agree(dt, lower, upper, agree_lower,
                                                       agree_upper)
        rate = TWO_PI / self.cycle_s
        self.depth_map.tick(dt, self.cycle_s)
        steer = self.patrol.step(x, y, theta, ice, algae, self.lo, self.hi,
                                 TeamInput(self.clock, self.passes, self.hurry, dt))
        direction = self.patrol.view.direction
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
            self.phase_des = desired_phase_step(mine, rate, dt, shift, consensus)
        self.phase_des = limit_lead(self.phase_des, phase, g.max_lead_rad)
        self._count_turns(before, lower if agree_lower else None)
        v = self._speed(steer, phase, rate, y, dt)
        v, omega = wheel_limited(v, v * steer.curvature, self.limits)
        depth_avg = self.depth_map.average(self.lo, self.hi)
        workload = depth_avg * (self.hi - self.lo)
        reach = max(g.shared_reach_m, g.shared_reach_fraction * (self.hi - self.lo))
        ends = self.depth_map.near_ends(self.lo, self.hi, reach)
        self.published = Neighbour(self.robot, self.lo, self.hi, self.phase_des, workload,
                                   self.turns, ends, self.cycle_s, self.passes, *chain)
        return Output(
            v, omega, self.lo, self.hi, phase, self.phase_des, workload, depth_avg,
            direction, steer.motion, self.turns, ends, self.cycle_s, self.passes,
        )

    def _arc_speed(self, steer: Steer, dt: float) -> float:
        """Full speed round an arc, but no further on its last tick than onto the leg's
        heading: at 10 Hz a tight arc turns a third of a radian a tick, and the leg
        would begin that far off its heading, its line a centimetre or two away, which
        on a 0.3 m segment is a tenth of a radian of eq. 3.1's phase."""
        p, lim = self.patrol, self.limits
        left = p.rotation_left()
        if left is None or steer.curvature == 0.0:
            return lim.v_max
        return min(lim.v_max, max(left, 0.0) / (abs(steer.curvature) * dt))

    def _speed(self, steer: Steer, phase: float, rate: float, y: float, dt: float) -> float:
        """Forward speed along the patrol (agent.phase.leg_speed, arc_may_begin): legs
        paced to end when the next arc is due, each arc begun so that its middle falls
        on the middle of its step of the team's phase."""
        assert self.phase_des is not None
        p, view, lim = self.patrol, self.patrol.view, self.limits
        lead = 0.5 * rate * p.arc_time_s(self.lo, self.hi, lim.v_max, lim.wheel_base_m)
        if steer.motion in (Motion.ENTER, Motion.UNDER, Motion.EXIT):
            if wrap_pi(self.phase_des - phase) < -self.gains.ahead_wait_rad:
                return 0.0  # well ahead of the team (one started ahead): let it come
            level = position_to_phase(view.grid_x, self.lo, self.hi, view.direction)
            middle = level + 0.5 * math.pi / view.passes
            time_left = wrap_pi(middle - lead - self.phase_des) / rate
            fast, slow = p.to_go(y, self.lo, self.hi, self.hurry)
            v = leg_speed(time_left, fast, slow, steer.measuring, lim.v_max,
                          p.config.measure_speed, p.config.min_leg_speed,
                          p.config.fine_speed)
            if steer.measuring and steer.dither is not None and v > 0.0:
                # a slow stretch's first tick a little longer, onto the offset it is
                # given of the lattice its ticks then follow: they fall at a new offset
                # from the edges it crosses (PatrolConfig.refined_measuring)
                step = v * dt
                along = y if steer.motion in IN_LEG else -y
                extra = (steer.dither * step - (along + step)) % step
                v = min(lim.v_max, v + extra / dt)
            return v
        if view.turned > p.config.arc_begun_rad:
            return self._arc_speed(steer, dt)
        if self.hurry or arc_may_begin(
                self.phase_des,
                position_to_phase(view.arc_from_grid, self.lo, self.hi, view.direction),
                position_to_phase(view.grid_x, self.lo, self.hi, view.direction), lead):
            return lim.v_max
        return 0.0

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
        self.clock = self.turns / math.pi


def initial_segment(robot: int, team: int, edge_lo: float, edge_hi: float) -> tuple[float, float]:
    """Robot ``robot``'s share of equal initial segments of a team of ``team``."""
    if not 0 <= robot < team:
        raise ValueError(f"robot id {robot} outside a team of {team}")
    width = (edge_hi - edge_lo) / team
    return edge_lo + robot * width, edge_lo + (robot + 1) * width if robot + 1 < team else edge_hi


def is_finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)
