"""The lawnmower patrol of thesis chapter 6 as a state machine, and the robot's
depth map from which its workload is measured.

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
(the pass spacing scales with its segment), so robots with equal work step their
phases together.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

from agent.phase import wrap_pi

HALF_PI = 0.5 * math.pi
FIRST_PASS_CANDIDATES = 24  # offsets tried for the first pass of a sweep
FIRST_PASS_MIN, FIRST_PASS_SPAN = 0.3, 1.7  # its length, in passes: 0.3 to 2
INTERIOR = 0.3  # a pass line within this fraction of a bin from its centre samples it


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
    passes_per_sweep: int = 16
    min_turn_radius_m: float = 0.04
    max_turn_radius_m: float = 0.2
    heading_gain: float = 4.0  # curvature per rad of heading error, 1/m
    line_gain: float = 3.0  # heading correction per m off the pass line, rad/m
    max_curvature: float = 10.0  # 1/m
    bin_m: float = 0.1  # resolution of the depth map
    end_inset_m: float = 0.05  # the last pass of a sweep stays this far inside the segment
    measure_zone_m: float = 0.08  # slow down this close to the depth the map expects
    measure_speed: float = 0.1  # m/s at least there (1 cm of depth per 10 Hz tick)

    def __post_init__(self) -> None:
        if self.passes_per_sweep < 1:
            raise ValueError("passes_per_sweep must be at least 1")
        if not 0 < self.min_turn_radius_m <= self.max_turn_radius_m:
            raise ValueError("need 0 < min_turn_radius_m <= max_turn_radius_m")
        if (self.min_depth_m <= 0 or self.margin_out_m <= 0 or self.bin_m <= 0
                or self.max_search_m <= 0):
            raise ValueError("depths, margin, search distance and bin must be positive")
        if self.measure_zone_m < 0 or self.measure_speed <= 0:
            raise ValueError("measure_zone_m must be >= 0 and measure_speed positive")


@dataclass
class DepthMap:
    """Patrol depth the robot measured at each bin along the edge: the median of the
    last ``keep`` samples, so one leg that strayed across a column boundary (and
    measured its neighbour) does not move the workload, and a changed profile is
    followed within two passes."""

    edge_lo: float
    bin_m: float
    default_m: float
    keep: int = 3
    depths: dict[int, float] = field(default_factory=dict)
    samples: dict[int, list[float]] = field(default_factory=dict)
    recorded: int = 0  # samples recorded so far, over all bins
    last_seen: dict[int, int] = field(default_factory=dict)  # bin -> ``recorded`` then

    def bin_of(self, s: float) -> int:
        return int(math.floor((s - self.edge_lo) / self.bin_m))

    def record(self, s: float, depth: float) -> None:
        b = self.bin_of(s)
        recent = self.samples.setdefault(b, [])
        recent.append(depth)
        del recent[: -self.keep]
        self.depths[b] = sorted(recent)[len(recent) // 2]
        self.recorded += 1
        self.last_seen[b] = self.recorded

    def staleness(self, s: float) -> int:
        """Samples recorded elsewhere since the bin at ``s`` was last sampled; a bin
        never sampled counts as staler than any sampled one. A line near a bin's side
        counts for nothing: a leg there wobbles across two columns and measures neither."""
        b = self.bin_of(s)
        if abs(s - self.edge_lo - (b + 0.5) * self.bin_m) > INTERIOR * self.bin_m:
            return 0
        seen = self.last_seen.get(b)
        return 10 * (self.recorded + 1) if seen is None else self.recorded - seen

    def average(self, lo: float, hi: float) -> float:
        """d_a over [lo, hi]: length-weighted mean of the measured profile, each bin
        not measured taking its nearest measured bin; ``default_m`` if none is."""
        if not self.depths or hi <= lo:
            return self.default_m
        known = sorted(self.depths)
        first = int(math.floor((lo - self.edge_lo) / self.bin_m))
        last = int(math.floor((hi - self.edge_lo) / self.bin_m))
        total = 0.0
        j = 0
        for b in range(first, last + 1):
            b_lo = max(lo, self.edge_lo + b * self.bin_m)
            b_hi = min(hi, self.edge_lo + (b + 1) * self.bin_m)
            if b_hi <= b_lo:
                continue
            while j + 1 < len(known) and abs(known[j + 1] - b) <= abs(known[j] - b):
                j += 1
            total += (b_hi - b_lo) * self.depths[known[j]]
        return total / (hi - lo)


@dataclass(frozen=True)
class Steer:
    """The patrol's steering: a curvature (omega = v * curvature)."""

    curvature: float
    motion: Motion
    measuring: bool = False  # near where this leg expects the algae to end: go slow


class Patrol:
    """The lawnmower state machine. Pure: feed it pose and sensing each tick."""

    def __init__(self, config: PatrolConfig, depth_map: DepthMap, x: float, direction: int = 1):
        self.config = config
        self.depth_map = depth_map
        self.motion = Motion.ENTER
        self.direction = 1 if direction >= 0 else -1
        self.line_x = x  # the pass line the straight legs hold
        self.entry_y: float | None = None  # where the ice edge was seen on the way in
        self.leg_y: float | None = None  # where the current straight leg began
        # Set while passes find no edge (nothing to measure): where the first of them
        # began, which each way out returns to.
        self.return_y: float | None = None
        self.exit_y: float | None = None  # where it was left on the way out
        self.turn_sign = 0  # +1 left (counter-clockwise), -1 right
        self.turn_radius = config.max_turn_radius_m
        self.sweeps = 0  # reversals so far
        self.turned = 0.0  # rotation so far in the current arc, rad
        self.prev_theta: float | None = None
        self.last_depth: float | None = None
        self.prev_y: float | None = None
        self.algae_depth: float | None = None  # deepest point of this leg with algae seen
        self.out_algae_top: float | None = None  # where the out leg first saw algae
        self.out_algae_x: float | None = None  # and at which x
        self.out_started_in_algae: bool | None = None

    def spacing(self, lo: float, hi: float) -> float:
        c = self.config
        raw = (hi - lo) / c.passes_per_sweep
        return min(max(raw, 2 * c.min_turn_radius_m), 2 * c.max_turn_radius_m)

    def _start_turn(self, lo: float, hi: float, heading_in: bool) -> None:
        """Choose the direction along the edge, then the arc that moves one pass."""
        c = self.config
        step = self.spacing(lo, hi)
        if not lo <= self.line_x <= hi:
            # The segment moved away from under the robot: head back at the widest pass.
            self.direction = 1 if self.line_x < lo else -1
            step = 2 * c.max_turn_radius_m
        else:
            nxt = self.line_x + self.direction * step
            # the last pass stops a little inside the end: exactly on the edge's end a
            # robot wobbling off the ice's side would see 'no ice' under the ice
            end = hi - c.end_inset_m if self.direction > 0 else lo + c.end_inset_m
            room = max(0.0, (end - self.line_x) * self.direction)
            if (nxt > hi or nxt < lo) and room >= max(0.25 * step, 2 * c.min_turn_radius_m):
                step = room  # a short last pass, so the sweep reaches the segment's end
            elif nxt > hi or nxt < lo:
                self.direction = -self.direction
                # The first pass of each sweep is shortened by a fraction that walks the
                # golden-ratio sequence, so successive sweeps sample new columns of the
                # depth profile instead of repeating the same pass lines.
                self.sweeps += 1
                step *= self._first_pass_fraction(lo, hi, step, heading_in)
                back = self.line_x + self.direction * step
                if back > hi or back < lo:  # narrower than a pass: head for the middle
                    self.direction = 1 if self.line_x < 0.5 * (lo + hi) else -1
        self.line_x += self.direction * step
        self.turn_radius = 0.5 * step
        # Heading +y, going +x is a right (clockwise) turn; heading -y it is a left one.
        self.turn_sign = -self.direction if heading_in else self.direction
        self.turned = 0.0

    def _first_pass_fraction(self, lo: float, hi: float, step: float, heading_in: bool
                             ) -> float:
        """How much of a pass the first pass of a new sweep moves: of fractions in
        [0.3, 1], the one whose in-legs (the sweep at the regular spacing) land on the
        depth map's stalest bins, so that every column of the profile gets sampled
        again within a sweep or two. Only in-legs count: an out-leg that starts inside
        algae deeper than the last turn cannot measure it. Candidates start at the
        golden-ratio walk, which breaks ties and keeps successive sweeps on new columns."""
        golden = (self.sweeps * 0.6180339887) % 1.0
        best, best_score = FIRST_PASS_MIN + FIRST_PASS_SPAN * golden, -1
        for j in range(FIRST_PASS_CANDIDATES):
            frac = FIRST_PASS_MIN + FIRST_PASS_SPAN * ((golden + j / FIRST_PASS_CANDIDATES) % 1)
            score = 0
            line = self.line_x + self.direction * frac * step
            inward = not heading_in  # the leg after this turn goes in, or out
            while lo <= line <= hi:
                score += self.depth_map.staleness(line) if inward else 0
                line += self.direction * step
                inward = not inward
            if score > best_score:
                best, best_score = frac, score
        return best

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
        from the turn depth, algae first seen marks the extent there; algae from the
        start only bounds it from below, and then nothing is recorded."""
        mid = y if prev_y is None else 0.5 * (prev_y + y)
        if self.out_started_in_algae is None:
            self.out_started_in_algae = algae
        if algae and self.out_algae_top is None:
            self.out_algae_top = mid
            self.out_algae_x = x
        if not ice and self.exit_y is None:
            self.exit_y = mid
            if not self.out_started_in_algae:
                c = self.config
                top = self.out_algae_top
                depth = c.min_depth_m if top is None else max(c.min_depth_m, top - mid)
                # where the algae was seen, if it was: the leg may have drifted since
                self.depth_map.record(x if self.out_algae_x is None else self.out_algae_x,
                                      depth)

    def _measured_depth(self, depth: float, prev_y: float | None, y: float) -> float:
        """The patrol depth of this pass: the minimum if algae ended before it, else
        the middle of the last tick with algae and this first tick without."""
        c = self.config
        if depth >= c.max_depth_m:
            return depth
        if self.algae_depth is None or self.algae_depth < c.min_depth_m or prev_y is None:
            return c.min_depth_m
        return max(c.min_depth_m, 0.5 * (self.algae_depth + depth))

    def step(self, x: float, y: float, theta: float, ice: bool, algae: bool,
             lo: float, hi: float) -> Steer:
        c = self.config
        rotation = 0.0 if self.prev_theta is None else wrap_pi(theta - self.prev_theta)
        self.prev_theta = theta
        prev_y, self.prev_y = self.prev_y, y
        if self.motion in (Motion.ENTER, Motion.EXIT) and self.leg_y is None:
            self.leg_y = y
        if self.motion is Motion.ENTER:
            if ice:
                # The edge lies between this tick and the last one: take the middle.
                self.entry_y = y if prev_y is None else 0.5 * (prev_y + y)
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
            if algae:
                self.algae_depth = depth
            if (depth >= c.min_depth_m and not algae) or depth >= c.max_depth_m:
                self.last_depth = self._measured_depth(depth, prev_y, y)
                self.depth_map.record(x, self.last_depth)  # where it was measured
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
            if self.turned >= math.pi - 0.03:
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
        return Steer(self._hold_line(x, theta, heading), self.motion, self._measuring(x, y))

    def _measuring(self, x: float, y: float) -> bool:
        """Whether this in-leg is near where the depth map expects the algae to end
        here, or anywhere under the ice if the map has no depth for this column yet."""
        if self.motion is not Motion.UNDER or self.entry_y is None:
            return False
        expected = self.depth_map.depths.get(self.depth_map.bin_of(x))
        return expected is None or abs(y - self.entry_y - expected) < self.config.measure_zone_m
