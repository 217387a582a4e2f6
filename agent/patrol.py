"""The lawnmower patrol of thesis chapter 6 as a state machine; it measures into the
robot's depth map (``agent.depthmap``).

Five motions: (1) ENTER: forward until the upward sensor sees the ice edge (at most
``max_search_m``: a robot whose pose has drifted off the ice's end or side would
otherwise drive on for ever; it turns back to where it began and goes on with the
sweep, recording nothing; an agent started with its robot under the ice turns at once
and goes out to find the edge);
(2) UNDER: on under the ice while algae is seen, at least ``min_depth_m``;
(3) TURN_UNDER: a 180 degree arc; (4) EXIT: back out until ``margin_out_m`` past
the edge (if the ice never ends, after ``max_depth_m`` plus ``max_search_m``);
(5) TURN_OUT: another 180 degree arc. Each arc moves the robot one pass
along the edge, towards ``hi`` or ``lo``; the direction reverses when the next pass
would leave the segment. Every robot makes the same number of passes per sweep
(the pass spacing scales with its segment), and the pass lines of every robot sit on
one grid of phases, set by the team's sweep count: so robots with equal work step
their phases together, level with each other.

The transitions are data (``TRANSITIONS``, each with its guard); what a leg has seen
lives in its own record (``InLeg``, ``OutLeg``), as an arc's turning does (``Arc``),
each new on entry. The controller tells the patrol the team's clock, passes and
hurry (``TeamInput``) and reads it through ``Patrol.view``.
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


ARCS = (Motion.TURN_UNDER, Motion.TURN_OUT)
IN_LEG = (Motion.ENTER, Motion.UNDER)


@dataclass(frozen=True)
class Transition:
    """One way from a motion to the next: ``when`` names the guard, a method of
    ``Patrol`` that the source motion's ``_decide_*`` asks. ``same_tick``: the target
    decides on this tick's sensing too (a leg that reaches its turn begins the arc at
    once); otherwise it acts from the next tick on, only steering on this one."""

    source: Motion
    target: Motion
    when: str
    same_tick: bool


TRANSITIONS: tuple[Transition, ...] = (
    Transition(Motion.ENTER, Motion.UNDER, "_sees_the_ice", same_tick=True),
    Transition(Motion.ENTER, Motion.TURN_UNDER, "_turns_back", same_tick=True),
    Transition(Motion.UNDER, Motion.TURN_UNDER, "_deep_enough", same_tick=True),
    Transition(Motion.TURN_UNDER, Motion.EXIT, "_arc_done", same_tick=False),
    Transition(Motion.EXIT, Motion.TURN_OUT, "_out_far_enough", same_tick=True),
    Transition(Motion.TURN_OUT, Motion.ENTER, "_arc_done", same_tick=False),
)
SUCCESSORS: dict[Motion, frozenset[Motion]] = {
    m: frozenset(t.target for t in TRANSITIONS if t.source is m) for m in Motion}
_BY_PAIR = {(t.source, t.target): t for t in TRANSITIONS}


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
    # A leg with time to spare measures slower than ``measure_speed``, down to this
    # (m/s; 0: never), its fast parts then reckoned at 0.8 v_max (agent.phase.leg_speed).
    # Off by default: on 10 general-suite cases (seed 5) 0.025 m/s lowered the relative
    # workload error on 6 but raised the position phase on all 10 and the believed-
    # workload gap on the two longest segments (docs/choices.md).
    fine_speed: float = 0.0
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
    # A leg with no new column in reach moves onto a step of its depth map's profile
    # not yet placed to 5 mm (``DepthMap.step_target``), as far as ``aim_fraction`` and
    # ``cover_m`` let it: on a long segment a step is otherwise placed only as the
    # grid's offsets happen to fall near it, a centimetre or two after 20 sweeps.
    aim_steps: bool = True
    # The first tick of each slow stretch of a leg goes a little further, onto the
    # offset frac(k / golden ratio) of a measuring tick from y = 0 (k counts the
    # stretches): at 0.1 m/s every tick is 1 cm, so without it a leg crosses an edge at
    # the same offset from its ticks as the leg before it did (its start, its pacing
    # and its zones repeat), and the middle of the two ticks about the crossing is off
    # the same way leg after leg, by up to 5 mm: on a straight edge one robot's
    # crossings averaged 0.8 mm above the edge, the other's 0.5 mm below, over 11 and
    # 5 m of algae 0.007 m^2 of workload between them that neither could see. (A
    # fraction of a tick added at random would not do: the offsets add up along the
    # patrol, and their sum is what the next crossing falls at.) The option also turns
    # on the depth map's three rules that were measured with it (DepthMap.refined).
    # Off by default for now, the map then b3c822c's bit for bit: on, the particle
    # filter's join case (tests/test_identity_process.py: a joiner parked in view,
    # robot 1 hidden behind it) loses the joiner for 10 s after it starts, the other
    # robots' motion a little changed; the filter's association of two tracks on one
    # blob is the fault (issue 23). On truth poses it is worth 144 of 160 general-suite
    # cases against 131 (docs/choices.md); the map's rules without the dither, 63 of 80
    # against 65.
    refined_measuring: bool = False
    # An arc that has turned a quarter ends once its heading is within this of the
    # leg's (or past it), rad: at 10 Hz a tight arc turns a third of a radian a tick.
    arc_end_rad: float = 0.03
    # An arc ends regardless after this much rotation, rad: one that began far off the
    # leg's heading (a robot pushed round) never meets it within a half turn.
    max_arc_rad: float = math.pi + 0.5
    # A leg keeps measuring slowly this far past the edge where the map has it, m: the
    # edge or the algae's end may have moved since.
    past_edge_m: float = 0.1
    # A short last pass of a sweep is made if at least this fraction of a pass is left
    # before the end inset; less, and the sweep reverses at once.
    min_last_pass: float = 0.25
    # An arc that has turned this much (rad) goes on at arc speed; before that the
    # controller holds it until the team's phase lets it begin.
    arc_begun_rad: float = 0.05
    # The ice and algae sensors as the robot has them (0, 0: readings of where it is,
    # as the ideal simulation gives them). A reading this late (s), through a comparator
    # that switches this far (m, the whole dead band) either side of the edge, changes
    # after the robot is past the edge by half the band plus how far it went in the
    # latency: every edge, crossing and algae end a leg finds is placed back by that,
    # along the way the robot went. From the sensors' data sheet (``btrack sim
    # --sensors lab`` gives its profile's figures, simworld.sensors).
    sensor_latency_s: float = 0.0
    sensor_band_m: float = 0.0

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
        if not 0 <= self.fine_speed <= self.measure_speed:
            raise ValueError("fine_speed must be in [0, measure_speed] (0: never)")
        if self.edge_zone_m < 0 or self.turn_margin_m < 0:
            raise ValueError("edge_zone_m and turn_margin_m must be >= 0")
        if not 0 <= self.aim_fraction <= 0.5:
            raise ValueError("aim_fraction must be in [0, 0.5] (of a pass)")
        if self.cover_m < self.max_spacing_m:
            raise ValueError("cover_m must be at least max_spacing_m")
        if not (0 < self.arc_end_rad and HALF_PI < self.max_arc_rad):
            raise ValueError("arc_end_rad must be positive and max_arc_rad past a quarter")
        if self.past_edge_m < 0 or not 0 < self.min_last_pass <= 1 or self.arc_begun_rad < 0:
            raise ValueError("past_edge_m and arc_begun_rad must be >= 0, "
                             "min_last_pass in (0, 1]")
        if self.sensor_latency_s < 0 or self.sensor_band_m < 0:
            raise ValueError("sensor_latency_s and sensor_band_m must be >= 0")


@dataclass(frozen=True)
class Steer:
    """The patrol's steering: a curvature (omega = v * curvature)."""

    curvature: float
    motion: Motion
    measuring: bool = False  # near an edge this leg measures: go slow
    # on the first tick of a slow stretch, go on to this offset (a fraction of the
    # tick) of the measuring tick's lattice along y (``PatrolConfig.refined_measuring``)
    dither: float | None = None


@dataclass(frozen=True)
class TeamInput:
    """What the controller tells the patrol at each tick, from the team."""

    # The team's sweep clock (the unwrapped desired phase over pi) as of the last
    # tick; None before the first. The first pass of a sweep is put on its grid.
    clock: float | None = None
    # The team's passes per sweep, taken at the start of each sweep (so a sweep's
    # lines all lie on one grid); None: the configured ``passes_per_sweep``.
    passes: int | None = None
    # The robot is well behind the team: measure nothing slowly (its samples and
    # crossings are ROUGH).
    hurry: bool = False
    # The control period, s: how far a late reading moved (``sensor_latency_s``).
    dt: float | None = None


@dataclass(frozen=True)
class PatrolView:
    """What the controller reads of the patrol to pace it."""

    motion: Motion
    direction: int  # along the edge, +1 towards hi
    grid_x: float  # the pass line on the team's grid the robot is on or arcs to
    arc_from_grid: float  # the grid line the last arc left
    passes: int  # passes in this sweep
    turned: float  # rotation so far in the current (or last) arc, rad


@dataclass
class InLeg:
    """What one way in (ENTER, then UNDER) has seen; a new one on entry to ENTER."""

    start_y: float | None = None  # where it began, set on its first tick
    from_water: bool = False  # it has seen water: it will cross the edge
    entry_y: float | None = None  # where it saw the ice edge
    measures: bool = True  # it crossed the edge, so can measure the depth
    algae_depth: float | None = None  # its deepest point with algae seen, from entry_y
    turn_depth: float | None = None  # set once it has measured: turn there


@dataclass
class OutLeg:
    """What one way out (EXIT) has seen; a new one on entry to EXIT."""

    start_y: float | None = None  # where it began, set on its first tick
    exit_y: float | None = None  # where it left the ice
    algae_top: float | None = None  # where it first saw algae
    algae_x: float | None = None  # and at which x
    started_in_algae: bool | None = None  # whether it saw algae on its first tick


@dataclass
class Arc:
    """One 180 degree arc between passes; a new one as each arc begins."""

    sign: int  # +1 left (counter-clockwise), -1 right
    radius: float
    turned: float = 0.0  # rotation so far, rad


NO_TEAM = TeamInput()


@dataclass(frozen=True)
class Tick:
    """One tick's inputs to ``Patrol.step``, with what follows from the last tick."""

    x: float
    y: float
    theta: float
    ice: bool
    algae: bool
    prev_y: float | None  # the last tick's y
    rotation: float  # heading change since the last tick, rad
    lo: float
    hi: float
    team: TeamInput


class Patrol:
    """The lawnmower state machine (``TRANSITIONS``). Pure: feed it pose and sensing
    each tick, with what the team says (``TeamInput``); read ``view``."""

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
        self.in_leg = InLeg()
        self.out_leg = OutLeg()
        self.arc = Arc(0, config.max_turn_radius_m)
        # Set while passes find no edge (nothing to measure): where the first of them
        # began, which each way out returns to.
        self.return_y: float | None = None
        # Until its first tick: the robot stands where it stood when the agent began
        # (a restart may find it anywhere, under the ice too).
        self.placed = True
        self.sweeps = 0  # reversals so far
        self.passes = config.passes_per_sweep  # this sweep's, from TeamInput.passes
        self._deepest: tuple[tuple[int, int, int] | None, float] = (None, 0.0)  # a cache
        self.prev_theta: float | None = None
        self.prev_y: float | None = None
        self.last_depth: float | None = None  # the depth the last in-leg measured
        self.was_measuring = False  # whether the last tick went slowly to measure
        self.slow_run = False  # whether the last tick of this leg (not an arc) was slow
        self.stretches = 0  # slow stretches begun so far (``refined_measuring``)
        # Whether the last out leg that saw algae came upon it slowly: an out leg that
        # sees none records its sample with the kind this says.
        self.out_slow = False

    @property
    def view(self) -> PatrolView:
        return PatrolView(self.motion, self.direction, self.grid_x, self.arc_from_grid,
                          self.passes, self.arc.turned)

    def spacing(self, lo: float, hi: float) -> float:
        """The distance between passes: the segment over the team's passes per sweep,
        unclamped, so every robot's phase steps by pi / passes at every arc."""
        return (hi - lo) / self.passes

    def _plan(self, lo: float, hi: float, heading_in: bool,
              clock: float | None) -> tuple[float, int, bool]:
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
        if room >= c.min_last_pass * step:
            return self.grid_x + direction * room, direction, False  # a short last pass
        direction = -direction
        length = self._first_pass(lo, hi, step, heading_in, direction, clock)
        line = self.grid_x + direction * length
        if not lo <= line <= hi:  # narrower than a pass: head for the middle
            direction = 1 if self.grid_x < 0.5 * (lo + hi) else -1
            line = self.grid_x + direction * length
        return line, direction, True

    def _start_turn(self, lo: float, hi: float, heading_in: bool,
                    team: TeamInput = NO_TEAM) -> None:
        """Choose the next pass line, then the arc from where the robot is onto it."""
        line, direction, new_sweep = self._plan(lo, hi, heading_in, team.clock)
        self.arc_from_x, self.arc_from_grid = self.line_x, self.grid_x
        self.sweeps += new_sweep
        if new_sweep:
            self.passes = self.config.passes_per_sweep if team.passes is None else team.passes
        self.direction = direction
        self.grid_x = line
        self.line_x = self._aim(line, lo, hi)
        # Heading +y, going +x is a right (clockwise) turn; heading -y it is a left one.
        self.arc = Arc(-direction if heading_in else direction,
                       self._arc_radius(abs(self.line_x - self.x)))

    def _first_pass(self, lo: float, hi: float, step: float, heading_in: bool,
                    direction: int, clock: float | None) -> float:
        """The length of the first pass of a new sweep: onto the team's grid, unless a
        bin of the profile that matters has not been measured, when its line is
        chosen to reach the stalest bins instead."""
        if clock is not None and not self.depth_map.gap(lo, hi):
            on_grid = self._grid_first_pass(lo, hi, step, heading_in, direction, clock)
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
                         direction: int, clock: float) -> float | None:
        """The first pass onto the team's grid: the sweep's lines at (g + j) passes from
        the end it starts at, so every robot's phase takes the same levels (eq. 3.1
        scales each segment to pi). g walks the golden ratio from sweep to sweep of the
        same direction, and is the same for every robot, as it comes from the team's
        sweep count; each robot chooses which of its lines are in-legs (the pass
        length, up to two passes) by the staleness of the bins they sample."""
        offset = (round(clock) * GOLDEN) % 1.0  # of the lines from lo, this sweep
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
        already; then on the nearest such middle. With no such column, on the place
        within that reach where a sample best places a step of the profile
        (``aim_steps``). Never more than ``cover_m`` from the last leg (the arc from it
        begins now), nor so far back that the next line of the grid would be."""
        c, depth_map = self.config, self.depth_map
        step = self.spacing(lo, hi)
        reach = c.aim_fraction * step
        last, after = self.arc_from_x, line + self.direction * step  # the legs either side
        inside_lo = max(lo + c.end_inset_m, line - reach, last - c.cover_m, after - c.cover_m)
        inside_hi = min(hi - c.end_inset_m, line + reach, last + c.cover_m, after + c.cover_m)
        if not depth_map.known(depth_map.bin_of(line)) and depth_map.staleness(line) > 0:
            return line  # already in a new column's middle
        best = line
        for b in range(depth_map.bin_of(inside_lo), depth_map.bin_of(inside_hi) + 1):
            centre = depth_map.centre(b)
            if (not depth_map.known(b) and inside_lo <= centre <= inside_hi
                    and (best == line or abs(centre - line) < abs(best - line))):
                best = centre
        if best == line and c.aim_steps:  # no new column: a step to place?
            target = depth_map.step_target(inside_lo, inside_hi)
            if target is not None:
                best = target
        return best

    def _turn_depth(self, lo: float, hi: float, depth: float, clock: float | None) -> float:
        """How deep an in-leg that has measured its column goes on before it turns:
        ``turn_margin_m`` past the algae its map expects under the next pass line (the
        deepest it knows in the segment if that column is new), so the out-leg there
        starts below the algae and measures it too."""
        c = self.config
        dm = self.depth_map
        line, _, _ = self._plan(lo, hi, True, clock)
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
            values += [d for b, d in dm.floors.items() if first <= b <= last]
            self._deepest = (key, max(values, default=self.config.min_depth_m))
        return self._deepest[1]

    def to_go(self, y: float, lo: float, hi: float, hurry: bool = False) -> tuple[float, float]:
        """What is left of this straight leg as the map expects it: (metres at full
        speed, metres at the measuring speed), the latter the parts of the zones of
        ``_measuring`` still ahead (none when ``hurry``, as at this tick's step). (0, 0)
        in an arc."""
        c, leg, out = self.config, self.in_leg, self.out_leg
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
            base = leg.entry_y if leg.entry_y is not None else y
            end = base + (leg.turn_depth if leg.turn_depth is not None else turn)
        elif self.motion is Motion.EXIT:
            out_edge = out.exit_y if out.exit_y is not None else (
                edge if edge is not None else leg.entry_y)
            if out_edge is None:
                return 0.0, 0.0
            end = out_edge - c.margin_out_m
            if (not hurry and out.algae_top is None
                    and out.started_in_algae is not True and edge is not None
                    and known is not None):
                zones.append((edge + known, edge + known + c.edge_zone_m))
        else:
            return 0.0, 0.0
        if self.motion in IN_LEG and leg.turn_depth is None:
            expected_here = dm.expected_depths(self.x)
            if not expected_here:  # a new column: all its depth slowly
                zones.append((base, base + turn))
            for d in expected_here:  # (both depths of a step not yet placed)
                zones.append((base + d - c.measure_zone_m, base + d))
        a, z = min(y, end), max(y, end)
        slow = 0.0 if hurry else _covered(zones, a, z)
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
        if self.motion not in ARCS or self.arc.turned < HALF_PI:
            return None
        if self.prev_theta is None:
            return None
        heading = -HALF_PI if self.motion is Motion.TURN_UNDER else HALF_PI
        return self.arc.sign * wrap_pi(heading - self.prev_theta)

    def _hold_line(self, x: float, theta: float, heading: float) -> float:
        c = self.config
        offset = x - self.line_x
        # Heading +y, a small turn to the left moves -x; heading -y, to the right.
        correction = math.atan(c.line_gain * offset)
        desired = heading + correction if heading > 0 else heading - correction
        k = c.heading_gain * wrap_pi(desired - theta)
        return min(max(k, -c.max_curvature), c.max_curvature)

    def _sensed(self, y: float, prev_y: float | None, dt: float | None) -> float:
        """Where along the leg what a reading changed on lies: the middle of this tick
        and the last, back by how far the sensors' latency and dead band put the
        change past it (``sensor_latency_s``, ``sensor_band_m``; none by default)."""
        if prev_y is None:
            return y
        # (less a lag of 0.0, the default's, is the middle itself, bit for bit)
        return 0.5 * (prev_y + y) - self._lag(y, prev_y, dt)

    def _lag(self, y: float, prev_y: float | None, dt: float | None) -> float:
        """How far past where it changed (along y, signed as the robot went) a reading
        changes: the latency's distance at this tick's speed and half the dead band."""
        c = self.config
        if prev_y is None or not (c.sensor_latency_s or c.sensor_band_m) or y == prev_y:
            return 0.0
        step = y - prev_y
        late = step * c.sensor_latency_s / dt if dt else 0.0
        return late + math.copysign(0.5 * c.sensor_band_m, step)

    def _measure_on_the_way_out(self, x: float, y: float, prev_y: float | None,
                                ice: bool, algae: bool, dt: float | None) -> None:
        """The out leg samples the depth profile too, on its own pass line: coming out
        from the turn depth, algae first seen marks the extent there (from the ice edge
        the in-legs found); algae from the start only bounds it from below, and then
        nothing is recorded. A ROUGH sample if it came upon the algae at full speed
        (the map had no depth for the column), else a PRECISE one."""
        out = self.out_leg
        mid = self._sensed(y, prev_y, dt)
        if out.started_in_algae is None:
            out.started_in_algae = algae
            edge = self.depth_map.edge_y(x)
            if algae and edge is not None:  # the algae here reaches at least this deep
                self.depth_map.floor(x, y - edge)
        if algae and out.algae_top is None:
            self.out_slow = self.was_measuring
            out.algae_top = mid
            out.algae_x = x
        if not ice and out.exit_y is None:
            out.exit_y = mid
            if not out.started_in_algae:
                c = self.config
                top = out.algae_top
                at = x if out.algae_x is None else out.algae_x
                edge = self.depth_map.edge_y(at)
                depth = c.min_depth_m if top is None else max(
                    c.min_depth_m, top - (mid if edge is None else edge))
                # where the algae was seen, if it was: the leg may have drifted since
                self.depth_map.record(at, depth, PRECISE if self.out_slow else ROUGH,
                                      top if edge is not None else None)

    def _measured_depth(self, depth: float, prev_y: float | None, y: float,
                        dt: float | None) -> float:
        """The patrol depth of this pass: the minimum if algae ended before it, else
        the middle of the last tick with algae and this first tick without, from the
        ice edge the in-legs found."""
        c, leg = self.config, self.in_leg
        if depth >= c.max_depth_m:
            return depth
        if leg.algae_depth is None or leg.algae_depth < c.min_depth_m or prev_y is None:
            return c.min_depth_m
        measured = 0.5 * (leg.algae_depth + depth)
        assert leg.entry_y is not None
        edge = self.depth_map.edge_y(self.x)
        if edge is not None:
            measured += leg.entry_y - edge
        return max(c.min_depth_m, measured - self._lag(y, prev_y, dt))

    def _algae_top(self, depth: float, prev_y: float | None, y: float,
                   dt: float | None) -> float | None:
        """Where this in-leg saw the algae end (the y ``_measured_depth`` measures from
        the edge); None if its depth is not measured from the edge (the minimum, or
        the deepest the patrol goes) or no crossing is known here yet."""
        c, leg = self.config, self.in_leg
        if (depth >= c.max_depth_m or leg.algae_depth is None or prev_y is None
                or leg.algae_depth < c.min_depth_m or leg.entry_y is None
                or self.depth_map.edge_y(self.x) is None):
            return None
        return leg.entry_y + 0.5 * (leg.algae_depth + depth) - self._lag(y, prev_y, dt)

    def step(self, x: float, y: float, theta: float, ice: bool, algae: bool,
             lo: float, hi: float, team: TeamInput = NO_TEAM) -> Steer:
        """One tick: the motion decides on this tick's sensing and may take one of its
        ``TRANSITIONS``; a ``same_tick`` one lets the next motion decide too. Then the
        motion it ends in steers."""
        rotation = 0.0 if self.prev_theta is None else wrap_pi(theta - self.prev_theta)
        self.x = x
        self.prev_theta = theta
        tick = Tick(x, y, theta, ice, algae, self.prev_y, rotation, lo, hi, team)
        self.prev_y = y
        deciders = {Motion.ENTER: self._decide_enter, Motion.UNDER: self._decide_under,
                    Motion.TURN_UNDER: self._decide_arc, Motion.EXIT: self._decide_exit,
                    Motion.TURN_OUT: self._decide_arc}
        while True:
            target = deciders[self.motion](tick)
            if target is None or not self._go(target, tick):
                break
        return self._steer(tick)

    def _go(self, target: Motion, tick: Tick) -> bool:
        """Take the declared transition to ``target``, giving the motion entered its own
        fresh state (a leg's record, or the arc onto the next pass line). Returns
        whether the target decides on this tick too."""
        transition = _BY_PAIR.get((self.motion, target))
        if transition is None:
            raise ValueError(f"no transition {self.motion.name} -> {target.name} declared")
        if target is Motion.ENTER:
            self.in_leg = InLeg()
        elif target is Motion.EXIT:
            self.out_leg = OutLeg()
        elif target in ARCS:
            self._start_turn(tick.lo, tick.hi, target is Motion.TURN_UNDER, tick.team)
        self.motion = target
        return transition.same_tick

    def _decide_enter(self, tick: Tick) -> Motion | None:
        """On in until the ice edge: there the leg measures the edge (if it crossed
        it) and goes UNDER; no edge within ``max_search_m``: turn."""
        leg = self.in_leg
        if leg.start_y is None:
            leg.start_y = tick.y
        if not tick.ice:
            leg.from_water = True
        placed, self.placed = self.placed, False
        if placed and self._placed_under_the_ice(tick):
            return Motion.TURN_UNDER
        if self._sees_the_ice(tick):
            y, prev_y = tick.y, tick.prev_y
            # The edge lies between this tick and the last one: take the middle.
            leg.entry_y = self._sensed(y, prev_y, tick.team.dt)
            # A later leg that began under the ice (an edge that bends below the
            # pass line) crossed no edge: it measures nothing.
            leg.measures = leg.from_water
            if leg.measures:
                self.depth_map.cross(tick.x, leg.entry_y,
                                     PRECISE if self.was_measuring else ROUGH)
            self.return_y = None
            return Motion.UNDER
        if self._searched_too_far(tick):
            # No edge where this pose says it should be: back to where the leg
            # began (EXIT ends margin_out_m past exit_y), then the next pass line.
            if self.return_y is None:  # the first of a run of misses: no creeping in
                self.return_y = leg.start_y
            return Motion.TURN_UNDER
        return None

    def _sees_the_ice(self, tick: Tick) -> bool:
        return tick.ice

    def _placed_under_the_ice(self, tick: Tick) -> bool:
        """An agent started where its robot stood under the ice (a restart) knows
        neither how deep it is nor where the edge is: it turns and goes out to find the
        edge (EXIT ends past it) rather than on, deeper, where a turn depth counted from
        where it stands may pass the ice's far side, which it would take for the edge.
        Asked on the first tick only (``placed``)."""
        return tick.ice and not self.in_leg.from_water

    def _turns_back(self, tick: Tick) -> bool:
        return ((self.placed and self._placed_under_the_ice(tick))
                or self._searched_too_far(tick))

    def _searched_too_far(self, tick: Tick) -> bool:
        start = self.in_leg.start_y
        return start is not None and tick.y - start >= self.config.max_search_m

    def _decide_under(self, tick: Tick) -> Motion | None:
        """On under the ice while algae is seen (at least ``min_depth_m``): where it
        ends, record the depth and choose the turn depth; turn there."""
        c, leg = self.config, self.in_leg
        depth = tick.y - (leg.entry_y if leg.entry_y is not None else tick.y)
        if leg.turn_depth is None:
            if tick.algae:
                leg.algae_depth = depth
            if (depth >= c.min_depth_m and not tick.algae) or depth >= c.max_depth_m:
                self.last_depth = self._measured_depth(depth, tick.prev_y, tick.y,
                                                       tick.team.dt)
                if leg.measures:
                    self.depth_map.record(  # where it was measured
                        tick.x, self.last_depth, PRECISE if self.was_measuring else ROUGH,
                        self._algae_top(depth, tick.prev_y, tick.y, tick.team.dt))
                leg.turn_depth = self._turn_depth(tick.lo, tick.hi, depth, tick.team.clock)
        return Motion.TURN_UNDER if self._deep_enough(depth) else None

    def _deep_enough(self, depth: float) -> bool:
        turn_depth = self.in_leg.turn_depth
        return turn_depth is not None and (depth >= turn_depth
                                           or depth >= self.config.max_depth_m)

    def _decide_exit(self, tick: Tick) -> Motion | None:
        """Back out, sampling the algae's end, until ``margin_out_m`` past the edge
        (past where a missed pass began; or, if the ice never ends, after
        ``max_depth_m`` plus ``max_search_m``)."""
        c, out = self.config, self.out_leg
        if out.start_y is None:
            out.start_y = tick.y
        if self.return_y is not None:  # this pass missed the edge
            if out.exit_y is None:
                out.exit_y = self.return_y + c.margin_out_m
        else:
            self._measure_on_the_way_out(tick.x, tick.y, tick.prev_y, tick.ice, tick.algae,
                                         tick.team.dt)
        far = out.start_y is not None and out.start_y - tick.y >= c.max_depth_m + c.max_search_m
        if far and out.exit_y is None:  # the ice never ended: a sensor or the pose
            out.exit_y = tick.y + c.margin_out_m  # is wrong; turn back out here
        return Motion.TURN_OUT if self._out_far_enough(tick) else None

    def _out_far_enough(self, tick: Tick) -> bool:
        exit_y = self.out_leg.exit_y
        return exit_y is not None and tick.y <= exit_y - self.config.margin_out_m

    def _decide_arc(self, tick: Tick) -> Motion | None:
        """Round the arc until it is on the next leg's heading."""
        self.arc.turned += self.arc.sign * tick.rotation
        if not self._arc_done(tick.theta):
            return None
        return Motion.EXIT if self.motion is Motion.TURN_UNDER else Motion.ENTER

    def _arc_done(self, theta: float) -> bool:
        """The arc ends on the leg's heading (+-y), whatever heading it began with."""
        c, arc = self.config, self.arc
        heading = -HALF_PI if self.motion is Motion.TURN_UNDER else HALF_PI
        return ((arc.turned >= HALF_PI and arc.sign * wrap_pi(heading - theta) <= c.arc_end_rad)
                or arc.turned >= c.max_arc_rad)

    def _steer(self, tick: Tick) -> Steer:
        """An arc's fixed curvature, or a straight leg holding its line."""
        if self.motion in ARCS:
            self.slow_run = False
            return Steer(self.arc.sign / self.arc.radius, self.motion)
        heading = HALF_PI if self.motion in IN_LEG else -HALF_PI
        self.was_measuring = self._measuring(tick.x, tick.y, tick.team.hurry)
        dither = None
        if self.was_measuring and not self.slow_run and self.config.refined_measuring:
            dither = (self.stretches * GOLDEN) % 1.0
            self.stretches += 1
        self.slow_run = self.was_measuring
        return Steer(self._hold_line(tick.x, tick.theta, heading), self.motion,
                     self.was_measuring, dither)

    def _measuring(self, x: float, y: float, hurry: bool) -> bool:
        """Whether this leg is about to cross an edge it measures, so goes slowly: on
        the way in, the ice edge where the in-legs found it (from ``edge_zone_m`` before
        it); under the ice, near where the depth map expects the algae to end, or
        anywhere if the map has no depth for this column yet (near both depths of a
        step it has not placed yet); on the way out, the algae's end where the map
        expects it (from ``edge_zone_m`` before it), if the leg began below it. Never
        while the robot hurries to catch up with the team."""
        c, leg, out = self.config, self.in_leg, self.out_leg
        if hurry:
            return False
        if self.motion is Motion.ENTER:
            edge = self.depth_map.edge_y(x)
            return edge is not None and -c.edge_zone_m < y - edge < c.past_edge_m
        if self.motion is Motion.EXIT:
            if out.started_in_algae is not False or out.algae_top is not None:
                return False
            edge = self.depth_map.edge_y(x)
            expected = self.depth_map.depths.get(self.depth_map.bin_of(x))
            return (edge is not None and expected is not None
                    and -c.past_edge_m < y - edge - expected < c.edge_zone_m)
        if self.motion is not Motion.UNDER or leg.entry_y is None or leg.turn_depth is not None:
            return False
        depths = self.depth_map.expected_depths(x)
        return not depths or any(abs(y - leg.entry_y - d) < c.measure_zone_m for d in depths)


def _covered(zones: list[tuple[float, float]], a: float, z: float) -> float:
    """How much of [a, z] the zones (bottom, top) cover, overlaps counted once."""
    covered, reach = 0.0, a
    for bottom, top in sorted(zones):
        lo, hi = max(bottom, reach), min(top, z)
        if hi > lo:
            covered += hi - lo
            reach = hi
    return covered
