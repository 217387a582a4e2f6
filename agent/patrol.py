"""The lawnmower patrol of thesis chapter 6 as a state machine; it measures into the
robot's depth map (``agent.depthmap``).

Five motions: (1) ENTER: forward until the upward sensor sees the ice edge (at most
``max_search_m``: a robot whose pose has drifted off the ice's end or side would
otherwise drive on for ever; it turns back to where it began and goes on with the
sweep, recording nothing);
(2) UNDER: on under the ice while algae is seen, at least ``min_depth_m``;
(3) TURN_UNDER: a 180 degree arc; (4) EXIT: back out until ``margin_out_m`` past
the edge (if the ice never ends, after ``max_depth_m`` plus ``max_search_m``);
(5) TURN_OUT: another 180 degree arc. Each arc moves the robot one pass
along the edge, towards ``hi`` or ``lo``; the direction reverses when the next pass
would leave the segment. Every robot makes the same number of passes per sweep
(the pass spacing scales with its segment), and the pass lines of every robot sit on
one grid of phases, set by the team's sweep count: so robots with equal work step
their phases together, level with each other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from agent.depthmap import PRECISE, ROUGH, DepthMap
from agent.phase import wrap_pi

HALF_PI = 0.5 * math.pi
FIRST_PASS_CANDIDATES = 24  # offsets tried for the first pass of a sweep
FIRST_PASS_MIN, FIRST_PASS_SPAN = 0.3, 1.7  # its length, in passes: 0.3 to 2
ON_LINE_M = 1e-6  # a pass line this close to a segment's end is on it
GOLDEN = 0.6180339887


class Motion(Enum):
    ENTER = 1
    UNDER = 2
    TURN_UNDER = 3
    EXIT = 4
    TURN_OUT = 5


@dataclass(frozen=True)
class PatrolConfig:
    min_depth_m: float = 0.3
    margin_out_m: float = 0.3
    max_depth_m: float = 5.0  # turn back regardless, in case a sensor fails
    max_search_m: float = 2.0  # how far in to look for the edge before giving up
    passes_per_sweep: int = 16  # at least; the team makes more on long segments
    max_spacing_m: float = 0.3  # passes at most this far apart (a robot's width, about)
    min_turn_radius_m: float = 0.01  # a differential drive turns about its inner wheel
    max_turn_radius_m: float = 0.2
    heading_gain: float = 4.0  # curvature per rad of heading error, 1/m
    line_gain: float = 3.0  # heading correction per m off the pass line, rad/m
    max_curvature: float = 10.0  # 1/m
    bin_m: float = 0.1  # resolution of the depth map
    end_inset_m: float = 0.05  # the last pass of a sweep stays this far inside the segment
    measure_zone_m: float = 0.08  # slow down this close to the depth the map expects
    measure_speed: float = 0.1  # m/s there (1 cm of depth per 10 Hz tick)
    edge_zone_m: float = 0.08  # slow down this close before a known edge (ice, algae out)
    turn_margin_m: float = 0.05  # turn under the ice this far past the next pass's algae
    min_leg_speed: float = 0.025  # m/s: legs are paced to the team, never slower than this
    # Every in-leg goes on to the segment's deepest known depth before it turns, so all
    # of a robot's passes are as long and its path-length phase runs as its position
    # phase does; it costs distance, not time (the team's rate is set by the deepest
    # pass anyway). Off: turn past the algae, as the thesis's patrol.
    even_legs: bool = True
    # A pass line may move off the team's grid by up to this fraction of a pass onto
    # the middle of a column of its segment that has no depth measured yet, so that a
    # long segment (a pass of 0.3 m is three columns) is covered within a few sweeps
    # rather than as the grid's offsets happen to fall. The arcs keep the grid's time
    # (the controller paces by ``grid_x``): the cost is a position phase of at most
    # pi * aim_fraction / passes during that leg.
    aim_fraction: float = 0.25
    # Legs never further apart than this, aimed or not: a point of the edge between two
    # is then within a robot's radius (0.17 m) of one of them, seen every sweep.
    cover_m: float = 0.34

    def __post_init__(self) -> None:
        if self.passes_per_sweep < 1:
            raise ValueError("passes_per_sweep must be at least 1")
        if not 0 < self.min_turn_radius_m <= self.max_turn_radius_m:
            raise ValueError("need 0 < min_turn_radius_m <= max_turn_radius_m")
        if not 0 < self.max_spacing_m <= 2 * self.max_turn_radius_m:
            raise ValueError("max_spacing_m must be positive and at most two "
                             "max_turn_radius_m (an arc joins two passes)")
        if (self.min_depth_m <= 0 or self.margin_out_m <= 0 or self.bin_m <= 0
                or self.max_search_m <= 0):
            raise ValueError("depths, margin, search distance and bin must be positive")
        if self.measure_zone_m < 0 or self.measure_speed <= 0:
            raise ValueError("measure_zone_m must be >= 0 and measure_speed positive")
        if self.edge_zone_m < 0 or self.turn_margin_m < 0:
            raise ValueError("edge_zone_m and turn_margin_m must be >= 0")
        if not 0 <= self.aim_fraction <= 0.5:
            raise ValueError("aim_fraction must be in [0, 0.5] (of a pass)")
        if self.cover_m < self.max_spacing_m:
            raise ValueError("cover_m must be at least max_spacing_m")


@dataclass(frozen=True)
class Steer:
    """The patrol's steering: a curvature (omega = v * curvature)."""

    curvature: float
    motion: Motion
    measuring: bool = False  # near an edge this leg measures: go slow


class Patrol:
    """The lawnmower state machine. Pure: feed it pose and sensing each tick, and the
    team's sweep clock (``clock``: the unwrapped desired phase over pi) when known."""

    def __init__(self, config: PatrolConfig, depth_map: DepthMap, x: float, direction: int = 1):
        self.config = config
        self.depth_map = depth_map
        self.motion = Motion.ENTER
        self.direction = 1 if direction >= 0 else -1
        self.line_x = x  # the pass line the straight legs hold
        self.arc_from_x = x  # the line the last arc left
        # The same two on the team's grid, which the arcs are timed by and the next
        # line is planned from: the line itself but when aimed at a new column.
        self.grid_x = x
        self.arc_from_grid = x
        self.x = x  # where the robot is
        self.clock: float | None = None  # the team's sweep clock, set by the controller
        self.entry_y: float | None = None  # where the ice edge was seen on the way in
        self.leg_y: float | None = None  # where the current straight leg began
        # Set while passes find no edge (nothing to measure): where the first of them
        # began, which each way out returns to.
        self.return_y: float | None = None
        self.exit_y: float | None = None  # where it was left on the way out
        self.turn_depth: float | None = None  # set once an in-leg has measured: turn there
        self.turn_sign = 0  # +1 left (counter-clockwise), -1 right
        self.turn_radius = config.max_turn_radius_m
        self.sweeps = 0  # reversals so far
        # Passes per sweep: the team's number (``team_passes``, set by the controller
        # from the chain's decision) taken at the start of each sweep, so a sweep's
        # lines all lie on one grid.
        self.passes = config.passes_per_sweep
        self.team_passes = config.passes_per_sweep
        self._deepest: tuple[tuple[int, int, int] | None, float] = (None, 0.0)  # a cache
        self.turned = 0.0  # rotation so far in the current arc, rad
        self.prev_theta: float | None = None
        self.last_depth: float | None = None
        self.prev_y: float | None = None
        self.algae_depth: float | None = None  # deepest point of this leg with algae seen
        self.out_algae_top: float | None = None  # where the out leg first saw algae
        self.out_algae_x: float | None = None  # and at which x
        self.out_started_in_algae: bool | None = None
        self.was_measuring = False  # whether the last tick went slowly to measure
        # Set by the controller while the robot is well behind the team: it then
        # measures nothing slowly (its samples and crossings are ROUGH).
        self.hurry = False
        self.from_water = False  # this way in has seen water: it will cross the edge
        self.measures = True  # this in-leg crossed the edge, so can measure the depth
        self.out_slow = False  # whether the out leg came upon the algae slowly

    def spacing(self, lo: float, hi: float) -> float:
        """The distance between passes: the segment over the team's passes per sweep,
        unclamped, so every robot's phase steps by pi / passes at every arc."""
        return (hi - lo) / self.passes

    def _plan(self, lo: float, hi: float, heading_in: bool) -> tuple[float, int, bool]:
        """The next pass line, the direction along the edge to it, and whether it
        begins a new sweep. Changes nothing."""
        c = self.config
        step = self.spacing(lo, hi)
        if not lo - ON_LINE_M <= self.grid_x <= hi + ON_LINE_M:
            # The segment moved away from under the robot: head back at the widest pass.
            # (A line that the sum of its passes puts a rounding error past an end is
            # on it: taken for outside, it cost a 0.4 m pass off the team's grid.)
            # Onto its first pass, half a pass inside, in arcs of at most the widest pass.
            direction = 1 if self.grid_x < lo else -1
            target = lo + 0.5 * step if direction > 0 else hi - 0.5 * step
            jump = min(2 * c.max_turn_radius_m, abs(target - self.grid_x))
            return self.grid_x + direction * jump, direction, False
        direction = self.direction
        nxt = self.grid_x + direction * step
        if lo <= nxt <= hi:
            return nxt, direction, False
        # the last pass stops a little inside the end: exactly on the edge's end a
        # robot wobbling off the ice's side would see 'no ice' under the ice
        end = hi - c.end_inset_m if direction > 0 else lo + c.end_inset_m
        room = max(0.0, (end - self.grid_x) * direction)
        if room >= 0.25 * step:
            return self.grid_x + direction * room, direction, False  # a short last pass
        direction = -direction
        length = self._first_pass(lo, hi, step, heading_in, direction)
        line = self.grid_x + direction * length
        if not lo <= line <= hi:  # narrower than a pass: head for the middle
            direction = 1 if self.grid_x < 0.5 * (lo + hi) else -1
            line = self.grid_x + direction * length
        return line, direction, True

    def _start_turn(self, lo: float, hi: float, heading_in: bool) -> None:
        """Choose the next pass line, then the arc from where the robot is onto it."""
        line, direction, new_sweep = self._plan(lo, hi, heading_in)
        self.arc_from_x, self.arc_from_grid = self.line_x, self.grid_x
        self.sweeps += new_sweep
        if new_sweep:
            self.passes = self.team_passes
        self.direction = direction
        self.grid_x = line
        self.line_x = self._aim(line, lo, hi)
        self.turn_radius = self._arc_radius(abs(line - self.x))
        # Heading +y, going +x is a right (clockwise) turn; heading -y it is a left one.
        self.turn_sign = -direction if heading_in else direction
        self.turned = 0.0

    def _first_pass(self, lo: float, hi: float, step: float, heading_in: bool,
                    direction: int) -> float:
        """The length of the first pass of a new sweep: onto the team's grid, unless a
        bin of the profile that matters has not been measured, when its line is
        chosen to reach the stalest bins instead."""
        if self.clock is not None and not self.depth_map.gap(lo, hi):
            on_grid = self._grid_first_pass(lo, hi, step, heading_in, direction)
            if on_grid is not None:
                return on_grid
        return step * self._first_pass_fraction(lo, hi, step, heading_in, direction)

    def _in_leg_staleness(self, line: float, lo: float, hi: float, step: float,
                          heading_in: bool, direction: int) -> int:
        """How stale the bins are that a sweep's in-legs sample, from ``line`` on at the
        regular spacing. Only in-legs count: an out-leg that starts inside algae deeper
        than the last turn cannot measure it."""
        score = 0
        inward = not heading_in  # the leg after this turn goes in, or out
        while lo <= line <= hi:
            score += self.depth_map.staleness(line) if inward else 0
            line += direction * step
            inward = not inward
        return score

    def _grid_first_pass(self, lo: float, hi: float, step: float, heading_in: bool,
                         direction: int) -> float | None:
        """The first pass onto the team's grid: the sweep's lines at (g + j) passes from
        the end it starts at, so every robot's phase takes the same levels (eq. 3.1
        scales each segment to pi). g walks the golden ratio from sweep to sweep of the
        same direction, and is the same for every robot, as it comes from the team's
        sweep count; each robot chooses which of its lines are in-legs (the pass
        length, up to two passes) by the staleness of the bins they sample."""
        assert self.clock is not None
        offset = (round(self.clock) * GOLDEN) % 1.0  # of the lines from lo, this sweep
        g = offset if direction > 0 else (1.0 - offset) % 1.0  # from the end it starts at
        end = lo if direction > 0 else hi
        shortest = FIRST_PASS_MIN * step
        best, best_score = None, -1
        for m in range(4):
            line = end + direction * (g + m) * step
            length = (line - self.grid_x) * direction
            if length < shortest:
                continue
            if length > (FIRST_PASS_MIN + FIRST_PASS_SPAN) * step:
                break
            score = self._in_leg_staleness(line, lo, hi, step, heading_in, direction)
            if score > best_score:
                best, best_score = length, score
        return best

    def _first_pass_fraction(self, lo: float, hi: float, step: float, heading_in: bool,
                             direction: int) -> float:
        """How much of a pass the first pass of a new sweep moves, off the grid: of
        fractions in [0.3, 2], the one whose in-legs (the sweep at the regular spacing)
        land on the depth map's stalest bins, so that every column of the profile gets
        sampled again within a sweep or two. Candidates start at the golden-ratio walk,
        which breaks ties and keeps successive sweeps on new columns."""
        golden = ((self.sweeps + 1) * GOLDEN) % 1.0
        best, best_score = FIRST_PASS_MIN + FIRST_PASS_SPAN * golden, -1
        for j in range(FIRST_PASS_CANDIDATES):
            frac = FIRST_PASS_MIN + FIRST_PASS_SPAN * ((golden + j / FIRST_PASS_CANDIDATES) % 1)
            line = self.grid_x + direction * frac * step
            score = self._in_leg_staleness(line, lo, hi, step, heading_in, direction)
            if score > best_score:
                best, best_score = frac, score
        return best

    def _aim(self, line: float, lo: float, hi: float) -> float:
        """Where the leg of grid line ``line`` runs: on it, unless the middle of a
        column with no depth measured (``DepthMap.known``) lies within ``aim_fraction``
        of a pass of it and inside the segment, and the line is not in such a middle
        already; then on the nearest such middle. Never more than ``cover_m`` from the
        last leg (the arc from it begins now), nor so far back that the next line of the
        grid would be."""
        c, depth_map = self.config, self.depth_map
        step = self.spacing(lo, hi)
        reach = c.aim_fraction * step
        ahead = line + self.direction * (step - c.cover_m)  # the next line's cover
        behind_prev = (self.arc_from_x - c.cover_m, self.arc_from_x + c.cover_m)
        inside_lo = max(lo + c.end_inset_m, line - reach, behind_prev[0],
                        ahead if self.direction > 0 else -math.inf)
        inside_hi = min(hi - c.end_inset_m, line + reach, behind_prev[1],
                        ahead if self.direction < 0 else math.inf)
        if not depth_map.known(depth_map.bin_of(line)) and depth_map.staleness(line) > 0:
            return line  # already in a new column's middle
        best = line
        for b in range(depth_map.bin_of(inside_lo), depth_map.bin_of(inside_hi) + 1):
            centre = depth_map.centre(b)
            if (not depth_map.known(b) and inside_lo <= centre <= inside_hi
                    and (best == line or abs(centre - line) < abs(best - line))):
                best = centre
        return best

    def _turn_depth(self, lo: float, hi: float, depth: float) -> float:
        """How deep an in-leg that has measured its column goes on before it turns:
        ``turn_margin_m`` past the algae its map expects under the next pass line (the
        deepest it knows in the segment if that column is new), so the out-leg there
        starts below the algae and measures it too."""
        c = self.config
        dm = self.depth_map
        line, _, _ = self._plan(lo, hi, heading_in=True)
        expected = dm.depths.get(dm.bin_of(line))
        if expected is None:
            inside = [d for b, d in dm.depths.items() if dm.bin_of(lo) <= b <= dm.bin_of(hi)]
            expected = max(inside, default=depth)
        if c.even_legs:  # every leg as deep as the segment's deepest
            expected = max(expected, self.deepest(lo, hi))
        return min(c.max_depth_m, max(depth, expected + c.turn_margin_m))

    def _expected_depth(self, x: float, lo: float, hi: float) -> float:
        """The patrol depth the map expects at ``x``: its bin's, else the deepest known
        in [lo, hi], else the minimum."""
        dm = self.depth_map
        known = dm.depths.get(dm.bin_of(x))
        if known is not None:
            return known
        return max(self.deepest(lo, hi), self.config.min_depth_m)

    def deepest(self, lo: float, hi: float) -> float:
        """The deepest patrol depth known in [lo, hi] (own or shared), else the minimum."""
        dm = self.depth_map
        first, last = dm.bin_of(lo), dm.bin_of(hi)
        key = (dm.version, first, last)
        if self._deepest[0] != key:
            values = [d for b, d in dm.depths.items() if first <= b <= last]
            values += [d for b, d in dm.shared.items() if first <= b <= last]
            self._deepest = (key, max(values, default=self.config.min_depth_m))
        return self._deepest[1]

    def to_go(self, y: float, lo: float, hi: float) -> tuple[float, float]:
        """What is left of this straight leg as the map expects it: (metres at full
        speed, metres at the measuring speed), the latter the parts of the zones of
        ``_measuring`` still ahead. (0, 0) in an arc."""
        c = self.config
        dm = self.depth_map
        edge = dm.edge_y(self.x)
        known = dm.depths.get(dm.bin_of(self.x))
        expected = max(c.min_depth_m, self._expected_depth(self.x, lo, hi))
        if c.even_legs:
            expected = max(expected, self.deepest(lo, hi))
        turn = expected + c.turn_margin_m
        zones: list[tuple[float, float]] = []
        if self.motion is Motion.ENTER:
            base = (y + c.margin_out_m) if edge is None else edge
            end = base + turn
            if edge is not None:
                zones.append((edge - c.edge_zone_m, edge))  # ENTER ends at the edge
        elif self.motion is Motion.UNDER:
            base = self.entry_y if self.entry_y is not None else y
            end = base + (self.turn_depth if self.turn_depth is not None else turn)
        elif self.motion is Motion.EXIT:
            out_edge = self.exit_y if self.exit_y is not None else (
                edge if edge is not None else self.entry_y)
            if out_edge is None:
                return 0.0, 0.0
            end = out_edge - c.margin_out_m
            if (not self.hurry and self.out_algae_top is None
                    and self.out_started_in_algae is not True and edge is not None
                    and known is not None):
                zones.append((edge + known, edge + known + c.edge_zone_m))
        else:
            return 0.0, 0.0
        if self.motion in (Motion.ENTER, Motion.UNDER) and self.turn_depth is None:
            if known is None:  # a new column: all its depth slowly
                zones.append((base, base + turn))
            else:
                zones.append((base + known - c.measure_zone_m, base + known))
        a, z = min(y, end), max(y, end)
        slow = 0.0 if self.hurry else sum(max(0.0, min(z, top) - max(a, bottom))
                                          for bottom, top in zones)
        slow = min(slow, z - a)
        return z - a - slow, slow

    def arc_time_s(self, lo: float, hi: float, v_max: float, wheel_base_m: float) -> float:
        """How long an arc between two passes takes at full speed, its outer wheel at
        ``v_max`` (a tight arc is slow: the robot turns about a point near its wheel)."""
        radius = self._arc_radius(self.spacing(lo, hi))
        return math.pi * (radius + 0.5 * wheel_base_m) / v_max

    def _arc_radius(self, across_m: float) -> float:
        """The radius of a 180 degree arc that moves the robot ``across_m`` along the
        edge, within the configured bounds."""
        c = self.config
        return min(c.max_turn_radius_m, max(0.5 * c.min_turn_radius_m, 0.5 * across_m))

    def pass_need_s(self, lo: float, hi: float, v_max: float, wheel_base_m: float) -> float:
        """The time this robot's hardest pass (a leg at the deepest depth it knows on its
        segment, its measuring zones at the measuring speed, and an arc) takes when it
        goes as fast as it may: what it needs of the team's rate."""
        c = self.config
        depth = max(c.min_depth_m, self.deepest(lo, hi))
        leg = c.margin_out_m + depth + c.turn_margin_m
        # the zones of ``_measuring``: up to the ice edge and the algae's end on the way
        # in, up to the algae on the way out
        slow_in = min(leg, c.edge_zone_m + c.measure_zone_m)
        slow_out = min(leg, c.edge_zone_m)
        speed = min(v_max, c.measure_speed)
        legs = [(leg - slow) / v_max + slow / speed for slow in (slow_in, slow_out)]
        return max(legs) + self.arc_time_s(lo, hi, v_max, wheel_base_m)

    def rotation_left(self) -> float | None:
        """In an arc that has turned past a quarter, the rotation left to the leg's
        heading (rad; negative once past it); None otherwise."""
        if self.motion not in (Motion.TURN_UNDER, Motion.TURN_OUT) or self.turned < HALF_PI:
            return None
        if self.prev_theta is None:
            return None
        heading = -HALF_PI if self.motion is Motion.TURN_UNDER else HALF_PI
        return self.turn_sign * wrap_pi(heading - self.prev_theta)

    def _hold_line(self, x: float, theta: float, heading: float) -> float:
        c = self.config
        offset = x - self.line_x
        # Heading +y, a small turn to the left moves -x; heading -y, to the right.
        correction = math.atan(c.line_gain * offset)
        desired = heading + correction if heading > 0 else heading - correction
        k = c.heading_gain * wrap_pi(desired - theta)
        return min(max(k, -c.max_curvature), c.max_curvature)

    def _measure_on_the_way_out(self, x: float, y: float, prev_y: float | None,
                                ice: bool, algae: bool) -> None:
        """The out leg samples the depth profile too, on its own pass line: coming out
        from the turn depth, algae first seen marks the extent there (from the ice edge
        the in-legs found); algae from the start only bounds it from below, and then
        nothing is recorded. A ROUGH sample if it came upon the algae at full speed
        (the map had no depth for the column), else a PRECISE one."""
        mid = y if prev_y is None else 0.5 * (prev_y + y)
        if self.out_started_in_algae is None:
            self.out_started_in_algae = algae
        if algae and self.out_algae_top is None:
            self.out_slow = self.was_measuring
            self.out_algae_top = mid
            self.out_algae_x = x
        if not ice and self.exit_y is None:
            self.exit_y = mid
            if not self.out_started_in_algae:
                c = self.config
                top = self.out_algae_top
                at = x if self.out_algae_x is None else self.out_algae_x
                edge = self.depth_map.edge_y(at)
                depth = c.min_depth_m if top is None else max(
                    c.min_depth_m, top - (mid if edge is None else edge))
                # where the algae was seen, if it was: the leg may have drifted since
                self.depth_map.record(at, depth, PRECISE if self.out_slow else ROUGH,
                                      top if edge is not None else None)

    def _measured_depth(self, depth: float, prev_y: float | None, y: float) -> float:
        """The patrol depth of this pass: the minimum if algae ended before it, else
        the middle of the last tick with algae and this first tick without, from the
        ice edge the in-legs found."""
        c = self.config
        if depth >= c.max_depth_m:
            return depth
        if self.algae_depth is None or self.algae_depth < c.min_depth_m or prev_y is None:
            return c.min_depth_m
        measured = 0.5 * (self.algae_depth + depth)
        assert self.entry_y is not None
        edge = self.depth_map.edge_y(self.x)
        if edge is not None:
            measured += self.entry_y - edge
        return max(c.min_depth_m, measured)

    def _algae_top(self, depth: float, prev_y: float | None) -> float | None:
        """Where this in-leg saw the algae end (the y ``_measured_depth`` measures from
        the edge); None if its depth is not measured from the edge (the minimum, or
        the deepest the patrol goes) or no crossing is known here yet."""
        c = self.config
        if (depth >= c.max_depth_m or self.algae_depth is None or prev_y is None
                or self.algae_depth < c.min_depth_m or self.entry_y is None
                or self.depth_map.edge_y(self.x) is None):
            return None
        return self.entry_y + 0.5 * (self.algae_depth + depth)

    def step(self, x: float, y: float, theta: float, ice: bool, algae: bool,
             lo: float, hi: float) -> Steer:
        c = self.config
        self.x = x
        rotation = 0.0 if self.prev_theta is None else wrap_pi(theta - self.prev_theta)
        self.prev_theta = theta
        prev_y, self.prev_y = self.prev_y, y
        if self.motion in (Motion.ENTER, Motion.EXIT) and self.leg_y is None:
            self.leg_y = y
            self.from_water = False
        if self.motion is Motion.ENTER and not ice:
            self.from_water = True
        if self.motion is Motion.ENTER:
            if ice:
                # The edge lies between this tick and the last one: take the middle.
                self.entry_y = y if prev_y is None else 0.5 * (prev_y + y)
                # A leg that began under the ice (an agent started where its robot
                # stood) crossed no edge: it measures nothing.
                self.measures = self.from_water
                if self.measures:
                    self.depth_map.cross(x, self.entry_y,
                                         PRECISE if self.was_measuring else ROUGH)
                self.algae_depth = None
                self.return_y = None
                self.motion = Motion.UNDER
            elif self.leg_y is not None and y - self.leg_y >= c.max_search_m:
                # No edge where this pose says it should be: back to where the leg
                # began (EXIT ends margin_out_m past exit_y), then the next pass line.
                if self.return_y is None:  # the first of a run of misses: no creeping in
                    self.return_y = self.leg_y
                self._start_turn(lo, hi, heading_in=True)
                self.motion = Motion.TURN_UNDER
        if self.motion is Motion.UNDER:
            depth = y - (self.entry_y if self.entry_y is not None else y)
            if self.turn_depth is None:
                if algae:
                    self.algae_depth = depth
                if (depth >= c.min_depth_m and not algae) or depth >= c.max_depth_m:
                    self.last_depth = self._measured_depth(depth, prev_y, y)
                    if self.measures:
                        self.depth_map.record(  # where it was measured
                            x, self.last_depth, PRECISE if self.was_measuring else ROUGH,
                            self._algae_top(depth, prev_y))
                    self.turn_depth = self._turn_depth(lo, hi, depth)
            if self.turn_depth is not None and (depth >= self.turn_depth
                                                or depth >= c.max_depth_m):
                self.turn_depth = None
                self._start_turn(lo, hi, heading_in=True)
                self.motion = Motion.TURN_UNDER
        elif self.motion is Motion.EXIT:
            if self.return_y is not None:  # this pass missed the edge
                if self.exit_y is None:
                    self.exit_y = self.return_y + c.margin_out_m
            else:
                self._measure_on_the_way_out(x, y, prev_y, ice, algae)
            far = self.leg_y is not None and self.leg_y - y >= c.max_depth_m + c.max_search_m
            if far and self.exit_y is None:  # the ice never ended: a sensor or the pose
                self.exit_y = y + c.margin_out_m  # is wrong; turn back out here
            if self.exit_y is not None and y <= self.exit_y - c.margin_out_m:
                self._start_turn(lo, hi, heading_in=False)
                self.motion = Motion.TURN_OUT
        if self.motion in (Motion.TURN_UNDER, Motion.TURN_OUT):
            self.turned += self.turn_sign * rotation
            # The arc ends on the leg's heading (+-y), whatever heading it began with.
            heading = -HALF_PI if self.motion is Motion.TURN_UNDER else HALF_PI
            if ((self.turned >= HALF_PI and self.turn_sign * wrap_pi(heading - theta) <= 0.03)
                    or self.turned >= math.pi + 0.5):
                self.leg_y = None  # a straight leg begins
                if self.motion is Motion.TURN_UNDER:
                    self.motion = Motion.EXIT
                    self.exit_y = None
                    self.out_algae_top = None
                    self.out_algae_x = None
                    self.out_started_in_algae = None
                else:
                    self.motion = Motion.ENTER
                    self.entry_y = None
            else:
                return Steer(self.turn_sign / self.turn_radius, self.motion)
        heading = HALF_PI if self.motion in (Motion.ENTER, Motion.UNDER) else -HALF_PI
        self.was_measuring = self._measuring(x, y)
        return Steer(self._hold_line(x, theta, heading), self.motion, self.was_measuring)

    def _measuring(self, x: float, y: float) -> bool:
        """Whether this leg is about to cross an edge it measures, so goes slowly: on
        the way in, the ice edge where the in-legs found it (from ``edge_zone_m`` before
        it); under the ice, near where the depth map expects the algae to end, or
        anywhere if the map has no depth for this column yet; on the way out, the
        algae's end where the map expects it (from ``edge_zone_m`` before it), if the
        leg began below it. Never while the robot hurries to catch up with the team."""
        c = self.config
        if self.hurry:
            return False
        if self.motion is Motion.ENTER:
            edge = self.depth_map.edge_y(x)
            return edge is not None and -c.edge_zone_m < y - edge < 0.1
        if self.motion is Motion.EXIT:
            if self.out_started_in_algae is not False or self.out_algae_top is not None:
                return False
            edge = self.depth_map.edge_y(x)
            expected = self.depth_map.depths.get(self.depth_map.bin_of(x))
            return (edge is not None and expected is not None
                    and -0.1 < y - edge - expected < c.edge_zone_m)
        if self.motion is not Motion.UNDER or self.entry_y is None or self.turn_depth is not None:
            return False
        expected = self.depth_map.depths.get(self.depth_map.bin_of(x))
        return expected is None or abs(y - self.entry_y - expected) < c.measure_zone_m
