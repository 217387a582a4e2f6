"""The robot's depth map: the patrol depth it measured along the edge, and the ice
edge its in-legs crossed, from which its workload (eq. 3.2) is measured. Pure: the
patrol records into it, the controller integrates it and trades its ends' depths
with the neighbours."""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

INTERIOR = 0.3  # a pass line within this fraction of a bin from its centre samples it
SIDE_M = 0.015  # a sample this close to a bin's side may be of the next column
# The ice edge at a bin: a cubic through the crossings of this many bins either side.
# A line through +-0.25 m of a curved edge (waves down to 1.5 m long, 0.6 m high) is
# 3-5 mm off it, one way over a whole bend, and every depth measured there with it. A
# parabola through +-0.35 m is still up to 9 mm off at a bin's centre on the sharpest
# bends (the quartic term its window cannot follow), and where a robot's crossings are
# all on one side of the bin (its segment's ends) it spread too little for one and fell
# back to a line: on 29 segments of six curved edges, per 0.1 m the edge was 3.0 mm off
# (rms) and over a segment up to 4.4 mm^2 of workload. A cubic through the same
# crossings: 1.4 mm and 1.8 mm^2.
EDGE_POOL_BINS = 3
KEEP_CROSSINGS = 16  # per bin
EDGE_FIT_SPREAD_M = 0.02  # crossings spread less than this along the edge: no slope
EDGE_CURVE_SPREAD_M = 0.05  # and less than this: no curvature (a line)
EDGE_CURVE_CROSSINGS = 8  # nor with fewer crossings: a cubic through a few follows their noise
# nor unless it fits them better than the line by this F ratio: on the same straight and
# sloped edges the cubic's two more terms took the per-0.1 m error from 0.80 mm (a line)
# to 0.95 mm; with the test 0.81 mm, and on the curved ones 1.40 mm
EDGE_CURVE_F = 4.0
KEEP_POINTS = 16  # depth samples per bin that the workload's profile keeps, with where
# How much a depth sample is worth: a leg that crossed the algae's end slowly, measured
# from a well-known ice edge; one that crossed it at full speed (a tick is 5 cm: an
# out-leg in a column its map has no depth for); one taken on a bin's side, which
# may be the next column's. A bin keeps samples of its best kind.
SUSPECT, ROUGH, PRECISE = 0, 1, 2
# What a sample or crossing of each kind weighs: inverse variances, a tick of 1 cm at the
# measuring speed against one of 5 cm at full speed.
WEIGHT = {PRECISE: 25.0, ROUGH: 1.0, SUSPECT: 1.0}
SMOOTH_M = 0.05  # a depth sample is averaged with the samples this close to it
ROUGH_SD_M = 0.05 / math.sqrt(12.0)  # a ROUGH sample's noise: a 5 cm tick, uniform
SLOPE_SIGNIFICANCE = 2.0  # standard errors: a slope this sure is followed, not averaged
AGREE_M = 0.05  # that measured within this of it (across a step they differ more)
SPIKE_SPAN_M = 0.1  # a lone sample between two this close may be a stray (``_profile``)
# The algae may change while the team patrols (issue 18). A sample that contradicts
# what earlier samples near it say (``_expected_at``: one at its place, or two either
# side that agree) by more than STALE_M (twice a tick at full speed, 5 cm, and the
# edge's error together; none on a bin's side) says the algae there may have changed;
# a second one the same way within a cycle (one alone may be a leg that strayed across
# a step) says it did. From then on the map is changing: every bin keeps only its last
# KEEP_POINTS_CHANGING samples, a sample is stale after the team's cycle (``tick``, the
# time a sweep each way takes) and the profile takes a bin without a sample that recent
# from its neighbours (as one never sampled), a neighbour's depth not told for that
# long is dropped, a bin's depth takes its next sample of any kind once its own are
# that old, and a bin where a sample contradicts the earlier ones forgets at once its
# samples of before, of whatever kind, that disagree with the new one. QUIET_CYCLES
# cycles without a contradiction, the change is over: the map forgets the depths of
# bins not sampled since and keeps and averages its samples as before. On a map that
# does not change none of this happens (the thesis's twelve cases give the same
# summaries, field for field), and the map keeps KEEP_POINTS.
STALE_M = 0.1
SAME_PLACE_M = 0.01  # samples this close measured the same column: a slope moves them little
BRACKET_M = 0.03  # else samples this close either side, if they agree, say what it should be
KEEP_POINTS_CHANGING = 3
QUIET_CYCLES = 2.0  # no such sample for this many cycles: the change is over, keep more
# A step of the algae between two neighbouring samples of the profile that disagree
# (by more than AGREE_M) is placed at the middle between them: it costs up to half
# their distance times its rise of workload (a 1 m step between samples 4 cm apart,
# 0.02 m^2). ``step_target`` says where a leg's sample would take most of that off; a
# stretch narrower than RESOLVE_M is placed well enough (a 1 m step, 2.5 mm^2), and no
# leg is aimed within AIM_SIDE_M of a bin's side, where a leg that wobbles reads the
# next column as often as its own.
RESOLVE_M = 0.005
AIM_SIDE_M = 0.005


@dataclass
class DepthMap:
    """Patrol depth the robot measured along the edge, in two forms.

    Per bin (what the patrol plans with: where to slow down, how deep to turn): the
    mean of the last ``keep`` samples of the bin's best kind (PRECISE, ROUGH,
    SUSPECT) but the highest and lowest, so one leg that strayed across a column
    boundary does not move it, and a changed profile is followed within a few passes.

    As a profile (what the workload integrates, ``average``): the last KEEP_POINTS
    samples of each bin, each where it was taken. Passes land at new offsets sweep
    after sweep, so a step of the algae inside a bin is placed to within the
    samples' spacing, where the bin's one value would put it at the bin's side (on
    a 1 m step, 5 cm out is 0.05 m^2 of workload). A sample keeps where the algae
    ended (``top_y``), and its depth there is measured again from the ice edge the
    in-legs' crossings give now (a line through them): the crossings keep coming, so
    the edge a sample was first measured from (a few crossings, some at full speed,
    5 mm off on a straight edge) would otherwise stay in the workload for good."""

    edge_lo: float
    bin_m: float
    default_m: float
    keep: int = 3
    # the edge's bins, 0 to bins - 1 (None: not bounded, a ring's map): a leg that
    # strays past an end of the edge samples a bin off it, which it may plan with but
    # never tell the neighbours of (they refuse a state naming a bin off the edge)
    bins: int | None = None
    # where the edge ends (None: not bounded): a sample past it is of no column of the
    # edge, and the profile leaves it out (``_profile``)
    edge_hi: float | None = None
    # PatrolConfig.refined_measuring: smooth along a significant slope, leave out a fast
    # sample on a bin's side between two depths, expect a neighbour's depth in a bin
    # only it has measured (off: the map of b3c822c, bit for bit)
    refined: bool = False
    depths: dict[int, float] = field(default_factory=dict)
    samples: dict[int, list[float]] = field(default_factory=dict)
    recorded: int = 0  # samples recorded so far, over all bins
    last_seen: dict[int, int] = field(default_factory=dict)  # bin -> ``recorded`` then
    kind: dict[int, int] = field(default_factory=dict)  # bin -> the kind of its samples
    # Depths the neighbours measured near the ends they share with this robot: a bin
    # this robot has not measured itself (a sliver at its segment's end, or one the
    # boundary just handed over) takes the neighbour's value, not its nearest own bin's.
    shared: dict[int, float] = field(default_factory=dict)
    # per bin, the in-legs' crossings of the ice edge: (x, y, weight), WEIGHT's
    crossings: dict[int, list[tuple[float, float, float]]] = field(default_factory=dict)
    _edges: dict[int, tuple[float, ...] | None] = field(default_factory=dict)  # fits
    # bin -> its last KEEP_POINTS samples as (s, depth, kind, top_y, t), the kind before
    # a sample near the bin's side is marked SUSPECT (its place is known here); top_y
    # where the algae ended (None: a depth not measured from the edge, the minimum); t
    # the map's clock when it was taken
    points: dict[int, list[tuple[float, float, int, float | None, float]]] = field(
        default_factory=dict)
    version: int = 0  # counts every sample recorded and shared depth changed, for caches
    # the profile ``average`` integrates, built for one version: (version, where each
    # piece starts, the integral up to there, each piece's depth)
    _integral: tuple[int, list[float], list[float], list[float]] = (-1, [], [], [])
    # the profile's steps of that version, by place: (a, z, depth at a, depth at z) for
    # each two neighbouring samples it keeps that disagree by more than AGREE_M, on
    # level ground either side (``_steps``)
    _steps: list[tuple[float, float, float, float]] = field(default_factory=list)
    _learned: tuple[object, object] = (None, None)  # the last two tuples learned
    _ends: tuple[object, tuple[tuple[int, float], ...]] = (None, ())  # near_ends's, by key
    # the last sample that contradicted an earlier one at its place: (the sign of the
    # change it saw, when), waiting for another to say the algae changed
    contradicted: tuple[float, float] | None = None
    changing: bool = False  # the algae was seen to change: keep KEEP_POINTS_CHANGING
    now: float = 0.0  # the map's clock, s: the time its controller has run (``tick``)
    changed_t: float = 0.0  # when a sample last said the algae changed
    horizon_s: float = math.inf  # once changing, samples older than this are stale
    sampled_t: dict[int, float] = field(default_factory=dict)  # bin -> its depth's latest
    shared_t: dict[int, float] = field(default_factory=dict)  # bin -> last told, once changing
    # Bins with no depth of their own that a leg found algae in at some depth: the algae
    # there reaches at least that deep (``floor``). An out-leg that starts inside algae
    # deeper than its turn sees no end to it; a column deeper than every column the
    # robot knows is otherwise taken for as deep as its neighbours (a 1.5 m column
    # between two 0.3 m ones, never sampled in 1200 s, was 0.12 m^2 of workload).
    floors: dict[int, float] = field(default_factory=dict)

    def bin_of(self, s: float) -> int:
        return int(math.floor((s - self.edge_lo) / self.bin_m))

    def centre(self, b: int) -> float:
        """The middle of bin ``b`` along the edge."""
        return self.edge_lo + (b + 0.5) * self.bin_m

    def on_side(self, s: float) -> bool:
        """Whether ``s`` is within SIDE_M of its bin's side: a sample there may be of
        the next column."""
        offset = s - self.edge_lo - self.bin_of(s) * self.bin_m
        return min(offset, self.bin_m - offset) < SIDE_M

    def record(self, s: float, depth: float, kind: int = PRECISE,
               top_y: float | None = None) -> None:
        """A depth sample at ``s``; ROUGH for one taken at full speed. It counts for
        less (SUSPECT) within SIDE_M of a bin's side. ``top_y``: where the algae ended,
        if ``depth`` was measured from the ice edge (the profile measures it again from
        the edge known then, never below ``default_m``, the patrol's minimum depth)."""
        b = self.bin_of(s)
        on_side = self.on_side(s)
        changed = self._changed(b, s, depth, SUSPECT if on_side else kind)
        placed = self.points.setdefault(b, [])
        if changed:
            placed[:] = [p for p in placed if abs(p[1] - depth) <= STALE_M]
        placed.append((s, depth, kind, top_y, self.now))
        del placed[:-(KEEP_POINTS_CHANGING if self.changing else KEEP_POINTS)]
        self.version += 1
        if on_side:
            kind = SUSPECT
        best = self.kind.get(b, -1)
        if changed or (self.changing and self.now - self.sampled_t.get(b, self.now)
                       > self.horizon_s):  # the samples of before, of any kind, are stale
            best = -1
        if kind < best:
            return
        if kind > best:
            self.samples[b] = []
            self.kind[b] = kind
        recent = self.samples[b]
        recent.append(depth)
        del recent[: -self.keep]
        ordered = sorted(recent)
        if len(ordered) >= 3:
            ordered = ordered[1:-1]
        self.depths[b] = sum(ordered) / len(ordered)
        self.sampled_t[b] = self.now
        if kind > SUSPECT:
            self.floors.pop(b, None)  # measured: the bound has done its work
        self.recorded += 1
        if kind > SUSPECT:
            self.last_seen[b] = self.recorded

    def _begin_changing(self) -> None:
        """The algae was seen to change: from now on every bin keeps only its last
        KEEP_POINTS_CHANGING samples, and samples age out after ``horizon_s``."""
        if not self.changing:
            self.changing = True
            for placed in self.points.values():
                del placed[:-KEEP_POINTS_CHANGING]
            self.shared_t = dict.fromkeys(self.shared, self.now)
            self.version += 1

    def tick(self, dt: float, horizon_s: float) -> None:
        """The controller's tick of ``dt``: the map's clock runs on, and once the algae
        was seen to change, samples older than ``horizon_s`` (the team's cycle) leave
        the profile, unless none newer is left anywhere (a robot that sampled nothing
        for a cycle)."""
        self.now += dt
        self.horizon_s = horizon_s
        if not self.changing:
            return
        if self.now - self.changed_t > QUIET_CYCLES * horizon_s:
            # the change is over: the map averages as it did, and forgets the depths of
            # bins not sampled since (a neighbour's, or its own from long ago)
            self.changing = False
            for b in [b for b in self.depths if self.sampled_t.get(b, 0.0) < self.changed_t]:
                for table in (self.depths, self.samples, self.kind, self.last_seen):
                    table.pop(b, None)  # type: ignore[attr-defined]
            self.version += 1
            return
        before = self.now - horizon_s
        stale = [b for b in self.shared if self.shared_t.get(b, -math.inf) < before]
        for b in stale:  # a neighbour's depth of a bin it no longer tells of
            del self.shared[b]
            self.version += 1
        if not any(p[4] < before for placed in self.points.values() for p in placed):
            return
        if not any(p[4] >= before for placed in self.points.values() for p in placed):
            return
        for b in list(self.points):
            self.points[b] = [p for p in self.points[b] if p[4] >= before]
            if not self.points[b]:
                del self.points[b]
        self.version += 1

    def _changed(self, b: int, s: float, depth: float, kind: int) -> bool:
        """Whether this sample at ``s`` (of ``kind``, SUSPECT on a bin's side) says the
        algae at bin ``b`` changed: it contradicts one of the bin's earlier samples taken
        within SAME_PLACE_M of it (by more than STALE_M; neither on a bin's side), once
        the map is changing or as another contradiction the same way did within a cycle
        (the first of them alone may be a leg that strayed across a step)."""
        if kind == SUSPECT:
            return False
        expected = self._expected_at(b, s)
        if expected is None or abs(depth - expected) <= STALE_M:
            return False
        if self._agreed_near(b, s, depth):  # a step between its samples, not a change
            return False
        sign = math.copysign(1.0, depth - expected)
        before, self.contradicted = self.contradicted, (sign, self.now)
        if not self.changing and (before is None or before[0] != sign
                                  or self.now - before[1] > self.horizon_s):
            return False
        self._begin_changing()
        self.changed_t = self.now
        return True

    def _agreed_near(self, b: int, s: float, depth: float) -> bool:
        """Whether an earlier sample within BRACKET_M of ``s`` (on a bin's side too: a
        step may lie there) measured ``depth`` to STALE_M: then a sample that contradicts
        the one nearest it lies across a step from it, which samples on both sides have
        found before. On a map that changed, the earlier samples near a place all say
        the old depth; on a step inside a column, sampled sweep after sweep a few
        millimetres either side of it, two samples a centimetre apart across it said so
        twice within a cycle, and a static map was taken for a changing one (20 robots
        on 12 m of steps: a robot's believed workload 0.05 m^2, a fifth of it, off for
        380 s)."""
        for k in (b - 1, b, b + 1):
            for q, d, _, top, _ in self.points.get(k, ()):
                if (abs(q - s) <= BRACKET_M
                        and abs(self._depth_now(q, d, top) - depth) <= STALE_M):
                    return True
        return False

    def _expected_at(self, b: int, s: float) -> float | None:
        """What the earlier samples near ``s`` (none on a bin's side) say its depth is,
        each measured from the ice edge the crossings give now: the newest taken within
        SAME_PLACE_M of it; else the line between the nearest ones within BRACKET_M
        either side, if they agree to STALE_M / 2 (no step or steep slope between
        them); else None (nothing to tell a change by)."""
        left: tuple[float, float] | None = None
        right: tuple[float, float] | None = None
        for k in (b - 1, b, b + 1):
            for q, d, _, top, _ in reversed(self.points.get(k, ())):
                if self.on_side(q) or abs(q - s) > BRACKET_M:
                    continue
                # from the edge as the crossings give it now, as the new sample is: the
                # edge a sample was first measured from may have been centimetres off
                d = self._depth_now(q, d, top)
                if k == b and abs(q - s) <= SAME_PLACE_M:
                    return d
                if q < s and (left is None or q > left[0]):
                    left = (q, d)
                elif q > s and (right is None or q < right[0]):
                    right = (q, d)
        if left is None or right is None or abs(left[1] - right[1]) > 0.5 * STALE_M:
            return None
        frac = (s - left[0]) / (right[0] - left[0])
        return left[1] + frac * (right[1] - left[1])

    def floor(self, s: float, depth: float) -> None:
        """Algae was seen ``depth`` in from the edge at ``s``: a column whose depth is
        not yet measured reaches at least that deep."""
        b = self.bin_of(s)
        if self.kind.get(b, SUSPECT) > SUSPECT or depth <= self.floors.get(b, self.default_m):
            return
        self.floors[b] = depth
        self.version += 1

    def known(self, b: int) -> bool:
        """Whether bin ``b``'s depth is measured (not only on its side) or shared."""
        return self.kind.get(b, SUSPECT) > SUSPECT or b in self.shared

    def cross(self, s: float, y: float, kind: int = PRECISE) -> None:
        """An in-leg crossed the ice edge at ``y`` (the middle of the ticks around it),
        slowly (PRECISE: to half a centimetre) or at full speed (ROUGH)."""
        b = self.bin_of(s)
        seen = self.crossings.setdefault(b, [])
        seen.append((s, y, WEIGHT[kind]))
        del seen[:-KEEP_CROSSINGS]
        for k in range(b - EDGE_POOL_BINS, b + EDGE_POOL_BINS + 1):
            self._edges.pop(k, None)
        self.version += 1  # the profile's depths near here are measured from the edge

    def edge_y(self, s: float) -> float | None:
        """The ice edge at ``s``, None if no in-leg has crossed it near ``s`` yet: the
        cubic fitted (weighted by kind) through the crossings within EDGE_POOL_BINS
        bins, so a sloped or curved edge is not pulled towards its mean, and noise
        averages out over many crossings made at every offset from the ticks."""
        b = self.bin_of(s)
        if b not in self._edges:
            self._edges[b] = self._fit_edge(b)
        fit = self._edges[b]
        if fit is None:
            return None
        return _poly_at(fit, s - self.centre(b))

    def _fit_edge(self, b: int) -> tuple[float, ...] | None:
        """The edge near bin ``b`` as a polynomial in the offset from the bin's centre
        (its coefficients, lowest first), from the crossings near it: weighted least
        squares, a cubic where they spread enough along the edge, a line or their mean
        where they spread too little to tell a curvature or a slope."""
        seen = [c for k in range(b - EDGE_POOL_BINS, b + EDGE_POOL_BINS + 1)
                for c in self.crossings.get(k, ())]
        if not seen:
            return None
        centre = self.centre(b)
        w = sum(c[2] for c in seen)
        mx = sum(c[2] * (c[0] - centre) for c in seen) / w
        my = sum(c[2] * c[1] for c in seen) / w
        # about the crossings' mean place and in units of their spread, where the
        # normal equations are best conditioned
        s2 = sum(c[2] * (c[0] - centre - mx) ** 2 for c in seen) / w
        if s2 < EDGE_FIT_SPREAD_M ** 2:  # all at one place: their mean
            return (my,)
        scale = math.sqrt(s2)
        rows = [((c[0] - centre - mx) / scale, c[1] - my, c[2]) for c in seen]
        coef = _weighted_fit(rows, 1)
        if coef is None:
            return (my,)
        if s2 >= EDGE_CURVE_SPREAD_M ** 2 and len(seen) >= EDGE_CURVE_CROSSINGS:
            cubic = _weighted_fit(rows, 3)
            # the cubic where it fits the crossings better than a line by more than
            # their noise explains (an F test): on a straight or sloped edge the line's
            # fewer terms follow the noise less
            if cubic is not None:
                line_rss, cubic_rss = _rss(rows, coef), _rss(rows, cubic)
                spare = len(rows) - 4
                if (line_rss - cubic_rss) / 2 > EDGE_CURVE_F * cubic_rss / spare:
                    coef = cubic
        coef[0] += my
        # back to the bin's centre: y = sum c_j ((v - mx) / scale)^j, v the offset
        return _shifted(coef, mx, scale)

    def learn(self, depths: tuple[tuple[int, float], ...]) -> None:
        """A neighbour's published depths of the bins near its ends."""
        if self.changing:  # what a neighbour still tells is not stale
            for b, _ in depths:
                self.shared_t[b] = self.now
        if depths in self._learned:  # as last tick's: most ticks, from both sides
            return
        self._learned = (self._learned[-1], depths)
        for b, depth in depths:
            if self.shared.get(b) != depth:
                self.shared[b] = depth
                self.version += 1

    def near_ends(self, lo: float, hi: float, reach_m: float) -> tuple[tuple[int, float], ...]:
        """This robot's own measured depths of the bins within ``reach_m`` of either end
        of [lo, hi] and on the edge, for its neighbours."""
        # once changing, none not sampled for a cycle: the algae may be another now
        key: tuple[float, ...] = (
            self.version, self.bin_of(lo - reach_m), self.bin_of(lo + reach_m),
            self.bin_of(hi - reach_m), self.bin_of(hi + reach_m),
            *((self.now,) if self.changing else ()))
        if self._ends[0] != key:
            ends = [int(k) for k in key[1:5]]
            bins = set(range(ends[0], ends[1] + 1)) | set(range(ends[2], ends[3] + 1))
            if self.bins is not None:
                bins = {b for b in bins if 0 <= b < self.bins}
            fresh = self.now - self.horizon_s if self.changing else -math.inf
            self._ends = (key, tuple((b, self.depths[b]) for b in sorted(bins)
                                     if self.kind.get(b, SUSPECT) > SUSPECT
                                     and self.sampled_t.get(b, 0.0) >= fresh))
        return self._ends[1]

    def gap(self, lo: float, hi: float, tolerance_m: float = 0.02) -> bool:
        """Whether a bin inside [lo, hi] is not known and that matters: the nearest
        known bins either side of it differ by more than ``tolerance_m``."""
        first = self.bin_of(lo + 0.5 * self.bin_m)
        last = self.bin_of(hi - 0.5 * self.bin_m)

        def value(k: int) -> float | None:
            return self.depths.get(k, self.shared.get(k)) if self.known(k) else None

        for b in range(first, last + 1):
            if self.known(b):
                continue
            if b in self.floors and b not in self.shared:  # deeper than it was taken for
                return True
            below = next((v for k in range(b - 1, first - 2, -1)
                          if (v := value(k)) is not None), None)
            above = next((v for k in range(b + 1, last + 2)
                          if (v := value(k)) is not None), None)
            if below is not None and above is not None and abs(below - above) > tolerance_m:
                return True
        return False

    def staleness(self, s: float) -> int:
        """Samples recorded elsewhere since the bin at ``s`` was last sampled; a bin
        never sampled (but on its side) counts as staler than any sampled one. A line
        near a bin's side counts for nothing: a leg there wobbles across two columns and
        measures neither."""
        b = self.bin_of(s)
        if abs(s - self.centre(b)) > INTERIOR * self.bin_m:
            return 0
        seen = self.last_seen.get(b)
        return 10 * (self.recorded + 1) if seen is None else self.recorded - seen

    def average(self, lo: float, hi: float) -> float:
        """d_a over [lo, hi]: the length-weighted mean of the measured profile
        (``_profile``); ``default_m`` if nothing is measured."""
        if not self.depths or hi <= lo:
            return self.default_m
        starts, integral, values = self._profile()
        return (self._integrate(hi, starts, integral, values)
                - self._integrate(lo, starts, integral, values)) / (hi - lo)

    def _depth_now(self, s: float, depth: float, top_y: float | None) -> float:
        """A sample's depth measured from the ice edge as the crossings give it now."""
        if top_y is None:
            return depth
        edge = self.edge_y(s)
        return depth if edge is None else max(self.default_m, top_y - edge)

    @staticmethod
    def _integrate(x: float, starts: list[float], integral: list[float],
                   values: list[float]) -> float:
        """The profile's integral from its first piece's start to ``x`` (the first and
        last pieces reach on beyond it)."""
        j = max(0, bisect.bisect_right(starts, x) - 1)
        return integral[j] + values[j] * (x - starts[j])

    def _profile(self) -> tuple[list[float], list[float], list[float]]:
        """The profile of this version as pieces: where each starts (each ends where
        the next starts), the integral up to its start, its depth.

        Each sample's depth is first smoothed with the samples near it that agree
        with it (``_smoothed``). A bin with samples is split between them, each
        stretch the nearest sample's depth, the first and last reaching to the bin's
        sides: columns on the bin grid come out whole, a step or a slope inside a bin
        where its samples put it. A bin with no sample of its own (or only on its
        sides) takes a neighbour's value for it, else the line between the nearest
        sampled bins either side (the nearest one's beyond the last)."""
        if self._integral[0] == self.version:
            return self._integral[1:]
        own = sorted((s, self._depth_now(s, d, top), kind)
                     for placed in self.points.values() for s, d, kind, top, _ in placed)
        # A leg that strays past the edge's end leaves the ice sideways, which ends
        # the algae it saw: on a 24.01 m ramps map one 0.7 mm past the end read 0.56 m
        # where the last column is 0.94 m, and held the edge's last centimetre at
        # that for the rest of the run (0.0038 m^2). Such samples are not the edge's.
        inside = [row for row in own if self.edge_hi is None
                  or self.edge_lo <= row[0] <= self.edge_hi]
        own = inside or own
        by_bin: dict[int, list[tuple[float, float]]] = {}  # bin -> (place, smoothed depth)
        lone: dict[int, list[tuple[float, float]]] = {}  # bin -> its mixed side samples
        smoothed = _smoothed(own, self.refined)
        for i, ((p, _, kind), (v, alone)) in enumerate(zip(own, smoothed, strict=True)):
            b = self.bin_of(p)
            # A sample on a bin's side that no sample near it agrees with, off the line
            # between the samples either side of it, is a leg that wobbled across a
            # step there: its depth is between the two columns' (one at 0.90 m read
            # 0.78 m between columns of 0.30 m and 1.28 m, and held 8 mm of its bin:
            # 4 mm^2). A step that lies there is found by the samples either side of
            # it; on a steep ramp a sample alone is on that line, and kept. The same
            # test holds for a lone sample anywhere whose neighbours either side are
            # closer than SPIKE_SPAN_M: a column that narrow is rare, a sample from a
            # leg still converging onto its line after an arc or one taken while the
            # segment moved is not (on a 30 m steps map three such, 8-31 cm off, held
            # 0.01 m^2 for 4000 s).
            if alone and 0 < i < len(own) - 1 and (
                    self.on_side(p) or own[i + 1][0] - own[i - 1][0] < SPIKE_SPAN_M):
                (pa, _, _), (va, _) = own[i - 1], smoothed[i - 1]
                (pz, _, _), (vz, _) = own[i + 1], smoothed[i + 1]
                line = va + (vz - va) * (p - pa) / (pz - pa) if pz > pa else 0.5 * (va + vz)
                # one taken at full speed (ROUGH, a tick of 5 cm) on a bin's side between
                # two depths is no better than a mixed reading, on their line or not: one
                # between columns of 0.62 and 0.30 m read 0.41 m, 1.2 cm off their line,
                # and held 9 mm of its bin (1.8 mm^2)
                blurred = (self.refined and kind == ROUGH and self.on_side(p)
                           and abs(vz - va) > AGREE_M)
                if blurred or abs(v - line) > AGREE_M:
                    lone.setdefault(b, []).append((p, v))
                    continue
            by_bin.setdefault(b, []).append((p, v))
        for b, mixed in lone.items():  # the only samples of their bin: kept
            if b not in by_bin:
                by_bin[b] = mixed
        column = {b: sum(v for _, v in rows) / len(rows) for b, rows in by_bin.items()}
        kept = sorted(row for b, rows in by_bin.items() for row in rows
                      if not self._sides_only(b))
        self._steps = _steps(kept)
        known = sorted(column)
        first = min(known[0], min(self.shared, default=known[0]))
        last = max(known[-1], max(self.shared, default=known[-1]))
        starts: list[float] = []
        values: list[float] = []
        j = 0  # known[j] is the last sampled bin at or below b
        for b in range(first, last + 1):
            b_lo = self.edge_lo + b * self.bin_m
            while j + 1 < len(known) and known[j + 1] <= b:
                j += 1
            rows = by_bin.get(b)
            if rows and self._sides_only(b):
                rows = None
            if rows and len(rows) > 1:
                starts.append(b_lo)
                values.append(rows[0][1])
                for a, z in zip(rows, rows[1:], strict=False):
                    starts.append(0.5 * (a[0] + z[0]))
                    values.append(z[1])
                continue
            if rows:
                depth = column[b]
            elif b in self.shared:
                depth = self.shared[b]
            elif b < known[0]:
                depth = column[known[0]]
            elif j + 1 >= len(known):
                depth = column[known[-1]]
            else:
                below, above = known[j], known[j + 1]
                frac = (b - below) / (above - below)
                depth = (1 - frac) * column[below] + frac * column[above]
            if not rows and b not in self.shared:
                depth = max(depth, self.floors.get(b, depth))
            starts.append(b_lo)
            values.append(depth)
        integral = [0.0]
        for k in range(1, len(starts)):
            integral.append(integral[-1] + values[k - 1] * (starts[k] - starts[k - 1]))
        self._integral = (self.version, starts, integral, values)
        return starts, integral, values

    def _sides_only(self, b: int) -> bool:
        """Whether bin ``b`` has only samples on its sides, which may be the next
        column's, and a neighbour's value for it: the profile takes that value."""
        return self.kind.get(b) == SUSPECT and b in self.shared

    def steps(self) -> list[tuple[float, float, float, float]]:
        """The profile's steps (``_steps``): (a, z, depth at a, depth at z), by a."""
        if self.depths:
            self._profile()
        return self._steps

    def step_target(self, lo: float, hi: float) -> float | None:
        """Where in [lo, hi] a leg would best place a step of the profile: of the
        stretches between two samples that disagree, the middle of a stretch's part in
        [lo, hi] (moved off a bin's side by AIM_SIDE_M) where a sample takes the most
        workload error off; None if no stretch there is still RESOLVE_M wide about
        such a place."""
        best, best_score = None, 0.0
        for a, z, va, vz in self.steps():
            if z <= lo or a >= hi:
                continue
            aim = self._off_side(0.5 * (max(a, lo) + min(z, hi)))
            if not (min(aim - a, z - aim) > 0.5 * RESOLVE_M and lo <= aim <= hi):
                continue
            # the workload error a sample at ``aim`` takes off, expected over where in
            # (a, z) the step may be: rise * (aim - a) * (z - aim) / (z - a)
            score = abs(vz - va) * (aim - a) * (z - aim) / (z - a)
            if score > best_score:
                best, best_score = aim, score
        return best

    def _off_side(self, s: float) -> float:
        """``s``, or AIM_SIDE_M off its bin's side if it is nearer to it than that."""
        side = self.edge_lo + round((s - self.edge_lo) / self.bin_m) * self.bin_m
        if abs(s - side) >= AIM_SIDE_M:
            return s
        return side + AIM_SIDE_M if s >= side else side - AIM_SIDE_M

    def expected_depths(self, s: float) -> tuple[float, ...]:
        """The depths a leg at ``s`` may find the algae end at: none if its bin has no
        depth yet, its own or a neighbour's (``known``); both sides' of a step of the
        profile not yet placed to RESOLVE_M about ``s``; else the bin's depth. (A leg
        on a robot's last 4 cm of a bin its neighbour has measured went the whole 1.5 m
        at the measuring speed, 13 s where its neighbours took 5, and put the team's
        phase a pass out for a minute: 0.047 rad on the thesis's random algae.)"""
        b = self.bin_of(s)
        depth = self.depths.get(b, self.shared.get(b) if self.refined else None)
        if depth is None:
            return ()
        steps = self.steps()
        j = bisect.bisect_right(steps, (s, math.inf)) - 1
        if j >= 0:
            a, z, va, vz = steps[j]
            if a < s < z and z - a > RESOLVE_M:
                return (va, vz)
        return (depth,)


def _steps(kept: list[tuple[float, float]]) -> list[tuple[float, float, float, float]]:
    """The steps among samples (place, depth) sorted by place: two neighbours that
    disagree by more than AGREE_M, each agreeing with its own other neighbour (if it
    has one). On a ramp steep enough that neighbours disagree, their neighbours do too:
    a ramp is no step, and a sample between its two is on it already."""
    def agree(i: int, j: int) -> bool:
        return not 0 <= j < len(kept) or abs(kept[i][1] - kept[j][1]) <= AGREE_M

    return [(pa, pz, va, vz) for i, ((pa, va), (pz, vz)) in enumerate(zip(kept, kept[1:],
                                                                          strict=False))
            if abs(vz - va) > AGREE_M and agree(i, i - 1) and agree(i + 1, i + 2)]


def _smoothed(samples: list[tuple[float, float, int]],
              follow_slopes: bool = True) -> list[tuple[float, bool]]:
    """Each sample's depth (samples sorted by place) smoothed with the samples within
    SMOOTH_M of it that agree with it to AGREE_M: their weighted mean, or where they
    slope more than their noise explains (SLOPE_SIGNIFICANCE), the line fitted through
    them, at its place. Noise averages out along a column, a step between columns stays
    where the samples put it, and on a steep slope (a bloom's side, 3 cm of depth a cm
    along the edge) a sample at the end of a cluster is not pulled towards the
    cluster's middle: a mean there held 7 cm of a slope 2.5 cm too deep (0.002 m^2).
    With it, whether no other sample there agrees with it (while some other sample
    is there)."""
    out = []
    lo = 0
    n = len(samples)
    for p, d, _ in samples:
        while samples[lo][0] < p - SMOOTH_M:
            lo += 1
        near = []
        k = lo
        while k < n and samples[k][0] <= p + SMOOTH_M:
            q = samples[k]
            if abs(q[1] - d) <= AGREE_M:
                near.append((q[0] - p, q[1], WEIGHT[q[2]]))
            k += 1
        weight = sum(w for _, _, w in near)
        mean_v = sum(w * v for _, v, w in near) / weight
        value = mean_v
        if follow_slopes and len(near) >= 3:
            mean_u = sum(w * u for u, _, w in near) / weight
            suu = sum(w * (u - mean_u) ** 2 for u, _, w in near)
            if suu > 0.0:
                slope = sum(w * (u - mean_u) * (v - mean_v) for u, v, w in near) / suu
                # WEIGHT is an inverse variance in units of a ROUGH sample's (a tick of
                # 5 cm: 5 cm / sqrt(12)), so the slope's standard error is this
                if abs(slope) > SLOPE_SIGNIFICANCE * ROUGH_SD_M / math.sqrt(suu):
                    value = mean_v - slope * mean_u  # the line at u = 0, the sample's place
        out.append((value, len(near) == 1 and k - lo > 1))
    return out


def _weighted_fit(rows: list[tuple[float, float, float]], degree: int) -> list[float] | None:
    """The coefficients (lowest first) of the polynomial of ``degree`` in u that fits
    the rows (u, y, weight) by weighted least squares; None if they do not fix it (the
    normal equations singular). Pure Python: the agent imports no numpy."""
    n = degree + 1
    moments = [sum(w * u ** j for u, _, w in rows) for j in range(2 * n - 1)]
    rhs = [sum(w * y * u ** j for u, y, w in rows) for j in range(n)]
    a = [[moments[i + j] for j in range(n)] + [rhs[i]] for i in range(n)]
    for col in range(n):  # Gaussian elimination with partial pivoting
        pivot = max(range(col, n), key=lambda r: abs(a[r][col]))
        if abs(a[pivot][col]) <= 1e-12 * max(1.0, abs(moments[0])):
            return None
        a[col], a[pivot] = a[pivot], a[col]
        for r in range(col + 1, n):
            f = a[r][col] / a[col][col]
            for k in range(col, n + 1):
                a[r][k] -= f * a[col][k]
    coef = [0.0] * n
    for i in range(n - 1, -1, -1):
        coef[i] = (a[i][n] - sum(a[i][k] * coef[k] for k in range(i + 1, n))) / a[i][i]
    return coef


def _rss(rows: list[tuple[float, float, float]], coef: list[float]) -> float:
    """The weighted sum of squared residuals of the rows (u, y, weight) off ``coef``."""
    return sum(w * (y - _poly_at(coef, u)) ** 2 for u, y, w in rows)


def _poly_at(coef: Sequence[float], u: float) -> float:
    """The polynomial of coefficients ``coef`` (lowest first) at ``u`` (Horner)."""
    y = 0.0
    for c in reversed(coef):
        y = y * u + c
    return y


def _shifted(coef: list[float], shift: float, scale: float) -> tuple[float, ...]:
    """The polynomial p((v - shift) / scale) as coefficients in v, lowest first."""
    out = [0.0] * len(coef)
    for c in reversed(coef):  # Horner: out = out * t + c, with t = (v - shift) / scale
        grown = [0.0] * len(coef)
        for j, x in enumerate(out[:-1]):  # out's degree is below len(coef) - 1 here
            grown[j] -= x * shift / scale
            grown[j + 1] += x / scale
        grown[0] += c
        out = grown
    return tuple(out)
