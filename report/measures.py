"""The measures every report prints (DESIGN.md "Measures"): pure functions over arrays.

Phase (thesis eq. 3.1, with the case condition read as the direction of travel),
phase and workload errors per neighbour pair (eq. 3.2, 3.3), steady-state error,
time to converge, revisit time (idleness) along the edge against the partition
optimum, standing still, speed-up. No I/O, no clock. ``team_measures`` gives all of
them for a team's arrays on one time grid, with or without a recording.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

# the report's angles are arrays: the agents' own functions, over arrays
from agent.phase import position_to_phase_array as position_phase
from agent.phase import wrap_pi_array as wrap_pi

TWO_PI = 2.0 * math.pi

# The report's bands and grids (``btrack report`` can override the two bands).
PHASE_BAND_RAD = 0.15  # phase converged: max-over-pairs |e_phi| within this
WORKLOAD_BAND_M2 = 0.05  # workload converged: max-over-pairs |e_Psi| within this
# workload converged, relative: |e_Psi| within this fraction of the mean workload per
# robot (the absolute band above is sized for the thesis's 6 m edge and three robots)
WORKLOAD_REL_BAND = 0.005
CONVERGE_SMOOTH_S = 10.0  # converge on |e| averaged over about two patrol passes
STEADY_LAST = 0.25  # steady state: the last quarter of the run
REVISIT_FROM = 0.5  # revisit times over the second half of the run (several patrol cycles)
VISIT_MERGE_S = 1.0  # visits of a point closer than this count as one
POINT_STEP_M = 0.1  # revisit times of points this far apart along the edge
# below this speed a robot stands still: 1 mm per 0.1 s tick (odometry noise and
# the controller's creep are far above it, a stopped robot far below)
STILL_SPEED_M_S = 0.01


@dataclass(frozen=True)
class EdgeModel:
    """The edge as the measures see it (WorldInfo's fields): its ends, the true patrol
    depth and the local edge's y per bin of ``bin_m`` from ``edge_lo``. ``edge_y``
    empty: a straight edge at y = 0 (every recording made before WorldInfo had it)."""

    edge_lo: float
    edge_hi: float
    bin_m: float
    patrol_depth: Sequence[float]
    edge_y: Sequence[float] = ()  # () = straight at y 0
    robot_radius: float = 0.17
    # A map that changes (WorldInfo's frames): the times from which each of ``frames``
    # (a patrol depth per bin, as ``patrol_depth``) is the true one, the true depth the
    # line between consecutive frames; and the changes' windows, flat [t0, t1, ...].
    # No frames: ``patrol_depth`` all the run.
    frame_t: Sequence[float] = ()
    frames: Sequence[Sequence[float]] = ()
    change_windows: Sequence[float] = ()

    @property
    def length(self) -> float:
        """Length of the edge along x, m (what the robots' along-edge speed covers)."""
        return self.edge_hi - self.edge_lo

    def bin_centres(self, bins: int) -> np.ndarray:
        """x of the centres of the first ``bins`` bins, the last one clipped at edge_hi."""
        left = self.edge_lo + self.bin_m * np.arange(bins)
        return 0.5 * (left + np.minimum(left + self.bin_m, self.edge_hi))

    def local_edge(self, x: np.ndarray | float) -> np.ndarray:
        """The local edge's y at ``x``: linear between the bins' centres, the first and
        last bin's value beyond them; 0 for a straight edge. NaN where x is NaN."""
        x = np.asarray(x, dtype=float)
        if len(self.edge_y) == 0:
            return np.zeros(x.shape)
        ys = np.asarray(self.edge_y, dtype=float)
        return np.interp(x, self.bin_centres(ys.size), ys)

    @property
    def changes(self) -> list[tuple[float, float]]:
        """The map's changes, (t0, t1) each; none for a static map."""
        w = list(self.change_windows)
        return list(zip(w[0::2], w[1::2], strict=True))

    def workload(self, lo: np.ndarray | float, hi: np.ndarray | float,
                 t: np.ndarray | None = None) -> np.ndarray:
        """True workload of segments [lo, hi] (``true_workload``); NaN without a depth
        profile (a recording with no world). On a map that changes, the depth in force
        at the times ``t`` (the last axis of lo and hi)."""
        if len(self.patrol_depth) == 0:
            return np.full(np.broadcast(np.asarray(lo), np.asarray(hi)).shape, np.nan)
        if not self.frames or t is None:
            return true_workload(lo, hi, self.edge_lo, self.bin_m, self.patrol_depth)
        return self._workload_in_time(lo, hi, np.asarray(t, dtype=float))

    def _workload_in_time(self, lo: np.ndarray | float, hi: np.ndarray | float,
                          t: np.ndarray) -> np.ndarray:
        """``workload`` on the frames: each sample's between the frames either side of
        its time, in proportion; one frame's alone where both are the same (before,
        between and after the changes), or before the first and after the last."""
        shape = np.broadcast_shapes(np.shape(lo), np.shape(hi), t.shape)
        lo_a = np.broadcast_to(np.asarray(lo, dtype=float), shape)
        hi_a = np.broadcast_to(np.asarray(hi, dtype=float), shape)
        t_a = np.broadcast_to(t, shape)[(0,) * (len(shape) - 1)] if shape else t
        ft = np.asarray(self.frame_t, dtype=float)
        out = np.empty(shape)
        j = np.clip(np.searchsorted(ft, t_a, side="right") - 1, 0, ft.size - 1)
        for f in np.unique(j):
            cols = j == f
            here = true_workload(lo_a[..., cols], hi_a[..., cols], self.edge_lo, self.bin_m,
                                 self.frames[f])
            if f + 1 < ft.size and list(self.frames[f + 1]) != list(self.frames[f]):
                there = true_workload(lo_a[..., cols], hi_a[..., cols], self.edge_lo,
                                      self.bin_m, self.frames[f + 1])
                w = np.clip((t_a[cols] - ft[f]) / (ft[f + 1] - ft[f]), 0.0, 1.0)
                here = here + w * (there - here)
            out[..., cols] = here
        return out

    @property
    def total_workload(self) -> float:
        """True workload of the whole edge, m^2 (the map's last, if it changes); NaN
        without a depth profile."""
        if self.frames:
            return float(true_workload(self.edge_lo, self.edge_hi, self.edge_lo, self.bin_m,
                                       self.frames[-1]))
        return float(self.workload(self.edge_lo, self.edge_hi))

    def total_workload_at(self, t: np.ndarray) -> float | np.ndarray:
        """True workload of the whole edge at the times ``t``; ``total_workload`` (one
        number) on a static map."""
        if not self.frames or len(self.patrol_depth) == 0:
            return self.total_workload
        return self.workload(np.full(np.shape(t), self.edge_lo),
                             np.full(np.shape(t), self.edge_hi), t)


def hold(
    t_src: np.ndarray, values: np.ndarray, t: np.ndarray, max_age: float = math.inf
) -> np.ndarray:
    """``values`` (sampled at sorted ``t_src``) held at times ``t``: the latest sample at
    or before each time; NaN before the first sample or when it is older than ``max_age``."""
    t_src = np.asarray(t_src, dtype=float)
    values = np.asarray(values, dtype=float)
    t = np.asarray(t, dtype=float)
    out = np.full(t.shape, np.nan)
    if t_src.size == 0:
        return out
    idx = np.searchsorted(t_src, t, side="right") - 1
    ok = idx >= 0
    ok[ok] &= (t[ok] - t_src[idx[ok]]) <= max_age
    out[ok] = values[idx[ok]]
    return out


def neighbour_pairs(ids: Sequence[int]) -> list[tuple[int, int]]:
    """Neighbour pairs (i, i+1) of a chain: consecutive robot ids."""
    ids = sorted(ids)
    return list(zip(ids[:-1], ids[1:], strict=False))


def active_pairs(ids: Sequence[int], live: np.ndarray
                 ) -> tuple[list[tuple[int, int]], np.ndarray]:
    """Neighbour pairs of a chain over time (``live[j, k]``: robot ``ids[j]`` in the
    team at sample k): (a, b) is a pair while both are live and no live id lies between
    them (a robot that left makes its two neighbours a pair). Returns the pairs that
    ever occur and active[p, k]."""
    pairs, rows = [], []
    for ja in range(len(ids)):
        between = np.zeros(live.shape[1], dtype=bool)
        for jb in range(ja + 1, len(ids)):
            active = live[ja] & live[jb] & ~between
            if active.any():
                pairs.append((ids[ja], ids[jb]))
                rows.append(active)
            between |= live[jb]
    return pairs, np.array(rows, dtype=bool).reshape(len(rows), live.shape[1])


def pair_errors(
    values: Mapping[int, np.ndarray], pairs: Sequence[tuple[int, int]], wrap: bool
) -> np.ndarray:
    """Errors v_{i+1} - v_i per pair (rows) against time (columns), wrapped to (-pi, pi]
    for phases (thesis eq. 3.2, 3.3)."""
    if not pairs:
        return np.empty((0, 0))
    rows = [
        np.asarray(values[b], dtype=float) - np.asarray(values[a], dtype=float) for a, b in pairs
    ]
    errors = np.vstack(rows)
    return wrap_pi(errors) if wrap else errors


def path_length_phase(x: np.ndarray, y: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Phase from the path travelled: cycles start where ``direction`` switches from -1
    to +1 (reversal at lo); phase = 2 pi (path since cycle start) / (cycle's path length).
    The unfinished last cycle uses the previous cycle's length (clipped below 2 pi);
    NaN before the first complete cycle starts and where no cycle length is known."""
    x, y, direction = (np.asarray(v, dtype=float) for v in (x, y, direction))
    n = x.size
    phase = np.full(n, np.nan)
    if n < 2:
        return phase
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    starts = np.flatnonzero((direction[:-1] == -1) & (direction[1:] == 1)) + 1
    if starts.size < 2:
        return phase
    for c in range(starts.size - 1):
        a, b = starts[c], starts[c + 1]
        length = s[b] - s[a]
        if length > 0:
            phase[a:b] = TWO_PI * (s[a:b] - s[a]) / length
    last = starts[-1]
    prev_length = s[starts[-1]] - s[starts[-2]]
    if prev_length > 0:
        below = np.nextafter(TWO_PI, 0.0)
        phase[last:] = np.minimum(TWO_PI * (s[last:] - s[last]) / prev_length, below)
    return phase


def cumulative_depth(
    edge_lo: float, bin_m: float, depth: Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """Bin edges and the integral of the piecewise-constant patrol depth up to each edge."""
    bins = np.asarray(depth, dtype=float)
    edges = edge_lo + bin_m * np.arange(bins.size + 1)
    area = np.concatenate([[0.0], np.cumsum(bins * bin_m)])
    return edges, area


def true_workload(
    lo: np.ndarray | float,
    hi: np.ndarray | float,
    edge_lo: float,
    bin_m: float,
    depth: Sequence[float],
) -> np.ndarray:
    """Psi = integral of the true patrol depth over [lo, hi], partial bins interpolated
    (thesis eq. 3.2); zero depth outside the binned edge. NaN where lo or hi is NaN."""
    edges, area = cumulative_depth(edge_lo, bin_m, depth)
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    return np.interp(hi, edges, area) - np.interp(lo, edges, area)


def _finite(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    return a[np.isfinite(a)]


def nanmean(a: np.ndarray) -> float:
    f = _finite(a)
    return float(f.mean()) if f.size else math.nan


def nanmax(a: np.ndarray) -> float:
    f = _finite(a)
    return float(f.max()) if f.size else math.nan


def window_mask(t: np.ndarray, start_frac: float, end_frac: float) -> np.ndarray:
    """Samples in [start_frac, end_frac] of the run's time span."""
    t = np.asarray(t, dtype=float)
    if t.size == 0:
        return np.zeros(0, dtype=bool)
    t0, t1 = float(t[0]), float(t[-1])
    span = t1 - t0
    return (t >= t0 + start_frac * span) & (t <= t0 + end_frac * span)


def window_abs(
    t: np.ndarray, errors: np.ndarray, start_frac: float, end_frac: float
) -> tuple[float, float]:
    """Mean and maximum of |e| over all pairs and the samples in a fraction of the run."""
    errors = np.asarray(errors, dtype=float)
    if errors.size == 0:
        return math.nan, math.nan
    mask = window_mask(t, start_frac, end_frac)
    sel = np.abs(errors[:, mask])
    return nanmean(sel), nanmax(sel)


def steady_state(t: np.ndarray, errors: np.ndarray, last: float = 0.25) -> tuple[float, float]:
    """Steady-state error: mean and maximum of |e| over pairs and the last quarter."""
    return window_abs(t, errors, 1.0 - last, 1.0)


def max_over_pairs(errors: np.ndarray) -> np.ndarray:
    """max_i |e_i| per sample; NaN where no pair has a value."""
    errors = np.abs(np.asarray(errors, dtype=float))
    if errors.ndim == 1:
        return errors
    if errors.shape[0] == 0:
        return np.full(errors.shape[1], np.nan)
    filled = np.where(np.isfinite(errors), errors, -np.inf)
    top = filled.max(axis=0)
    return np.where(np.isfinite(top), top, np.nan)


def running_mean(t: np.ndarray, values: np.ndarray, window_s: float) -> np.ndarray:
    """Trailing mean of ``values`` over the last ``window_s`` seconds, skipping NaNs."""
    t = np.asarray(t, dtype=float)
    values = np.asarray(values, dtype=float)
    if window_s <= 0 or t.size < 2:
        return values
    known = np.isfinite(values)
    csum = np.concatenate([[0.0], np.cumsum(np.where(known, values, 0.0))])
    ccount = np.concatenate([[0], np.cumsum(known)])
    start = np.searchsorted(t, t - window_s, side="left")
    end = np.arange(1, t.size + 1)
    count = ccount[end] - ccount[start]
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (csum[end] - csum[start]) / count
    return np.where(count > 0, out, np.nan)


def converge_time(t: np.ndarray, errors: np.ndarray, band: float, smooth_s: float = 0.0
                  ) -> float:
    """Time (from the first sample) after which max-over-pairs |e|, averaged over the
    trailing ``smooth_s`` seconds, stays within ``band`` for the rest of the run; NaN if
    it never settles. The average spans a patrol pass, so the saw-tooth that the
    position-based phase makes within each pass does not count as leaving the band.
    Samples with no value are skipped."""
    return _band_time(t, errors, band, smooth_s, to_stay=True)


def recovery_time(t: np.ndarray, errors: np.ndarray, band: float, smooth_s: float = 0.0
                  ) -> float:
    """Time (from the first sample) at which max-over-pairs |e|, averaged over the
    trailing ``smooth_s`` seconds, first came back within ``band`` after having left
    it; 0 if it never left; NaN if it never came back. Unlike ``converge_time``, a later
    excursion does not undo the recovery: that belongs to the steady-state measures."""
    return _band_time(t, errors, band, smooth_s, to_stay=False)


def _band_time(t: np.ndarray, errors: np.ndarray, band: float, smooth_s: float,
               to_stay: bool) -> float:
    """Back within ``band`` after the last (``to_stay``) or the first excursion."""
    t = np.asarray(t, dtype=float)
    worst = running_mean(t, max_over_pairs(errors), smooth_s)
    known = np.flatnonzero(np.isfinite(worst))
    if t.size == 0 or known.size == 0:
        return math.nan
    outside = known[worst[known] > band]
    if outside.size == 0:
        return float(t[known[0]] - t[0])
    if to_stay:
        back = known[known > outside[-1]]
    else:
        back = known[(known > outside[0]) & (worst[known] <= band)]
    return float(t[back[0]] - t[0]) if back.size else math.nan


def crossings(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, edge: EdgeModel | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Times and x positions where a track crosses the local edge: sample pairs where
    h = y - edge_y(x) changes sign, the crossing where h, linear between the two
    samples, is zero. edge_y from ``edge.local_edge`` (linear between the bins'
    centres); without ``edge``, or for a straight one, the line y = 0. Pairs with a
    sample of unknown position (NaN) are skipped."""
    t, x, y = (np.asarray(v, dtype=float) for v in (t, x, y))
    if t.size < 2:
        return np.empty(0), np.empty(0)
    h = y if edge is None else y - edge.local_edge(x)
    known = np.isfinite(h)
    side = h >= 0
    k = np.flatnonzero((side[:-1] != side[1:]) & known[:-1] & known[1:])
    h0, h1 = h[k], h[k + 1]
    frac = np.where(h1 != h0, h0 / (h0 - h1), 0.0)
    return t[k] + frac * (t[k + 1] - t[k]), x[k] + frac * (x[k + 1] - x[k])


def sweep_index(t: np.ndarray, direction: np.ndarray, at_t: np.ndarray) -> np.ndarray:
    """Which sweep of a robot (how many times its ``direction``, sampled at sorted
    ``t``, had reversed by then) each of ``at_t`` falls in. Samples with no direction
    (NaN) hold the one before; 0 before the first sample or with none."""
    t = np.asarray(t, dtype=float)
    at_t = np.asarray(at_t, dtype=float)
    direction = np.asarray(direction, dtype=float)
    if t.size == 0:
        return np.zeros(at_t.size, dtype=np.int64)
    known = np.isfinite(direction)
    last_known = np.maximum.accumulate(np.where(known, np.arange(t.size), 0))
    held = direction[last_known]
    reversal = (held[1:] != held[:-1]) & np.isfinite(held[1:]) & np.isfinite(held[:-1])
    reversals = np.concatenate([[0], np.cumsum(reversal)])
    idx = np.clip(np.searchsorted(t, at_t, side="right") - 1, 0, t.size - 1)
    return reversals[idx].astype(np.int64)


def merge_visits(times: np.ndarray, merge_s: float) -> np.ndarray:
    """Sorted visit times with visits less than ``merge_s`` after the previous one dropped."""
    times = np.sort(np.asarray(times, dtype=float))
    if times.size == 0:
        return times
    keep = np.concatenate([[True], np.diff(times) >= merge_s])
    return times[keep]


def point_gaps(
    points: np.ndarray,
    visit_t: np.ndarray,
    visit_x: np.ndarray,
    radius: float,
    t_from: float,
    t_to: float,
    merge_s: float = 1.0,
    visit_group: np.ndarray | None = None,
) -> list[np.ndarray | None]:
    """For each point, the times between its consecutive visits in [t_from, t_to];
    None for a point seen fewer than twice there. A visit is a crossing within
    ``radius`` of the point; crossings of one point with the same ``visit_group`` (one
    robot's one sweep along its segment) count as one visit, at the first."""
    out: list[np.ndarray | None] = []
    for times in point_visits(points, visit_t, visit_x, radius, merge_s, visit_group):
        times = times[(times >= t_from) & (times <= t_to)]
        out.append(np.diff(times) if times.size >= 2 else None)
    return out


def point_visits(
    points: np.ndarray,
    visit_t: np.ndarray,
    visit_x: np.ndarray,
    radius: float,
    merge_s: float = 1.0,
    visit_group: np.ndarray | None = None,
) -> list[np.ndarray]:
    """For each point, the sorted times of its visits over the whole run, as
    ``point_gaps`` counts them."""
    visit_t = np.asarray(visit_t, dtype=float)
    visit_x = np.asarray(visit_x, dtype=float)
    order = np.argsort(visit_t, kind="stable")
    visit_t, visit_x = visit_t[order], visit_x[order]
    groups = None if visit_group is None else np.asarray(visit_group)[order]
    out = []
    for p in np.asarray(points, dtype=float):
        near = np.abs(visit_x - p) <= radius
        times = visit_t[near]
        if groups is not None and times.size:
            _, first = np.unique(groups[near], return_index=True)
            times = np.sort(times[first])
        out.append(merge_visits(times, merge_s))
    return out


def worst_idleness(visits: np.ndarray, t_from: float, t_to: float, t_start: float
                   ) -> float:
    """The worst idleness of a point over [t_from, t_to], as patrol benchmarks define
    it: the longest any moment of the window had waited since the point's last visit
    (since ``t_start``, the run's start, before its first). A visit before the window
    counts: a point last seen just before it has waited that long already at its start,
    and one the window sees once is not the whole window unvisited."""
    visits = np.asarray(visits, dtype=float)
    marks = np.concatenate([[t_start], visits[visits <= t_to], [t_to]])
    since, until = marks[:-1], np.minimum(marks[1:], t_to)
    overlap = until >= t_from
    return float((until[overlap] - since[overlap]).max())


def revisit_profile(
    gaps: Sequence[np.ndarray | None], t_from: float, t_to: float,
    worst: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and worst revisit time of each point: the worst is ``worst`` if given (the
    points' ``worst_idleness``), else the longest of its gaps; a point seen fewer than
    twice in the window has no mean (NaN) and, without ``worst``, the whole window as
    its worst."""
    mean = np.array([float(g.mean()) if g is not None else math.nan for g in gaps])
    if worst is None:
        worst = np.array([float(g.max()) if g is not None else t_to - t_from for g in gaps])
    return mean, np.asarray(worst, dtype=float)


def revisit_intervals(
    points: np.ndarray,
    visit_t: np.ndarray,
    visit_x: np.ndarray,
    radius: float,
    t_from: float,
    t_to: float,
    merge_s: float = 1.0,
    visit_group: np.ndarray | None = None,
) -> tuple[float, float]:
    """Mean (over every interval of every point) and worst time between consecutive
    visits of the points (``point_gaps``). A point seen fewer than twice in the window
    counts the whole window as its worst interval."""
    gaps = point_gaps(points, visit_t, visit_x, radius, t_from, t_to, merge_s, visit_group)
    return pooled_revisit(gaps, t_from, t_to)


def pooled_revisit(
    gaps: Sequence[np.ndarray | None], t_from: float, t_to: float,
    worst: np.ndarray | None = None,
) -> tuple[float, float]:
    """Mean over every interval of every point, and the worst point's worst."""
    mean, _, worst_s = idleness(gaps, t_from, t_to, worst)
    return mean, worst_s


def idleness(
    gaps: Sequence[np.ndarray | None], t_from: float, t_to: float,
    worst: np.ndarray | None = None,
) -> tuple[float, float, float]:
    """Idleness as patrol benchmarks report it: over every point and every interval
    between its consecutive visits in [t_from, t_to] (``point_gaps``), the mean and the
    standard deviation of the intervals, and the worst point's worst
    (``revisit_profile``: ``worst`` per point if given)."""
    known = [g for g in gaps if g is not None]
    pooled = np.concatenate(known) if known else np.empty(0)
    _, per_point = revisit_profile(gaps, t_from, t_to, worst)
    std = float(pooled.std()) if pooled.size else math.nan
    return nanmean(pooled), std, nanmax(per_point)


def edge_points(edge_lo: float, edge_hi: float, step: float = 0.1) -> np.ndarray:
    """Points every ``step`` metres over [edge_lo, edge_hi], both ends included."""
    n = int(math.floor((edge_hi - edge_lo) / step + 1e-9))
    return edge_lo + step * np.arange(n + 1)


def sweep_rate(
    tracks: Sequence[tuple[np.ndarray, np.ndarray]], t_from: float, t_to: float,
    sweeps: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
) -> float:
    """Team along-edge sweep rate n v over [t_from, t_to]. With each robot's sweeps
    (``sweeps``: per robot the times and directions of travel its agent published), the
    distance along the edge between its reversals (and the window's ends), so that a
    leg's wobble about its pass line, which goes nowhere along the edge, is not counted
    as patrol (on short segments it doubled the sum); without them, the sum of |dx|.
    ``tracks`` holds one (t, x) per robot."""
    duration = t_to - t_from
    if duration <= 0:
        return math.nan
    total = 0.0
    for j, (t, x) in enumerate(tracks):
        t = np.asarray(t, dtype=float)
        x = np.asarray(x, dtype=float)
        sel = (t >= t_from) & (t <= t_to) & np.isfinite(x)
        if sel.sum() < 2:
            continue
        ts, xs = t[sel], x[sel]
        if sweeps is not None and np.asarray(sweeps[j][0]).size >= 2:
            st, sd = (np.asarray(v, dtype=float) for v in sweeps[j])
            flips = st[1:][sd[1:] != sd[:-1]]
            at = np.concatenate([[ts[0]], flips[(flips > ts[0]) & (flips < ts[-1])], [ts[-1]]])
            total += float(np.abs(np.diff(np.interp(at, ts, xs))).sum())
        else:
            total += float(np.abs(np.diff(xs)).sum())
    return total / duration


def ideal_revisit(edge_length: float, team_sweep_rate: float) -> float:
    """Mean revisit time of an ideal team with the same along-edge speed: L / sweep
    rate (every point of the edge swept once per L / (n v) on average)."""
    if not team_sweep_rate > 0:
        return math.nan
    return edge_length / team_sweep_rate


def partition_optimum(edge_length: float, team_sweep_rate: float, closed: bool = False
                      ) -> float:
    """Worst idleness of the optimal partitioned patrol: n robots each sweeping back and
    forth over an equal share of an open edge of length L at along-edge speed v leave
    the ends of their shares unvisited for 2 L / (n v); on a closed edge (a ring, every
    robot going round the same way) L / (n v). n v is the team's measured along-edge
    sweep rate (``sweep_rate``)."""
    if not team_sweep_rate > 0:
        return math.nan
    return (1.0 if closed else 2.0) * edge_length / team_sweep_rate


def revisit_window(t: np.ndarray) -> tuple[float, float]:
    """The window of the revisit measures: the second half of the run."""
    t = np.asarray(t, dtype=float)
    return float(t[0] + REVISIT_FROM * (t[-1] - t[0])), float(t[-1])


def visit_gaps(
    tracks: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    edge: EdgeModel,
    t_from: float,
    t_to: float,
) -> tuple[np.ndarray, list[np.ndarray | None], np.ndarray]:
    """Points every POINT_STEP_M along the edge and, for each, the times between its
    consecutive visits in [t_from, t_to] (``point_gaps``) and its worst idleness over
    the window (``worst_idleness``, from the first track's start): a visit is a
    crossing of the local edge (``crossings``) within the robot radius of the point,
    one per robot sweep. ``tracks``: per robot, its track's t, x, y and the times and
    directions that tell its sweeps apart (``sweep_index``)."""
    visit_t, visit_x, visit_group = [np.empty(0)], [np.empty(0)], [np.empty(0, np.int64)]
    for j, (t, x, y, sweep_t, sweep_direction) in enumerate(tracks):
        tc, xc = crossings(t, x, y, edge)
        visit_t.append(tc)
        visit_x.append(xc)
        visit_group.append(j * 1_000_000 + sweep_index(sweep_t, sweep_direction, tc))
    points = edge_points(edge.edge_lo, edge.edge_hi, POINT_STEP_M)
    visits = point_visits(points, np.concatenate(visit_t), np.concatenate(visit_x),
                          edge.robot_radius, VISIT_MERGE_S, np.concatenate(visit_group))
    gaps: list[np.ndarray | None] = []
    for times in visits:
        inside = times[(times >= t_from) & (times <= t_to)]
        gaps.append(np.diff(inside) if inside.size >= 2 else None)
    starts = [float(tr[0][0]) for tr in tracks if len(tr[0])]
    t_start = min(starts) if starts else t_from
    worst = np.array([worst_idleness(v, t_from, t_to, t_start) for v in visits])
    return points, gaps, worst


def idleness_measures(
    gaps: Sequence[np.ndarray | None],
    t_from: float,
    t_to: float,
    team_sweep_rate: float,
    edge_length: float,
    closed: bool = False,
    worst_per_point: np.ndarray | None = None,
) -> dict[str, float]:
    """The revisit keys of ``team_measures``: idleness mean, standard deviation and
    worst (``idleness``, with each point's ``worst_idleness`` if given), the ideal
    mean L / (n v) (``ideal_revisit``), the partition optimum of the worst
    (``partition_optimum``) and the worst over that optimum."""
    mean, std, worst = idleness(gaps, t_from, t_to, worst_per_point)
    optimum = partition_optimum(edge_length, team_sweep_rate, closed)
    return {
        "revisit_mean_s": mean,
        "revisit_std_s": std,
        "revisit_worst_s": worst,
        "revisit_ideal_s": ideal_revisit(edge_length, team_sweep_rate),
        "revisit_optimum_s": optimum,
        "revisit_worst_ratio": worst / optimum if optimum > 0 else math.nan,
    }


def still_fraction(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    t_from: float,
    live: np.ndarray | None = None,
) -> float:
    """Standing still: the fraction of one robot's steps from ``t_from`` on (between
    samples both known and, with ``live``, both live) in which it moved less than
    STILL_SPEED_M_S times the step's duration (1 mm per 0.1 s tick). NaN with none."""
    t, x, y = (np.asarray(v, dtype=float) for v in (t, x, y))
    if t.size < 2:
        return math.nan
    dt = np.diff(t)
    step = np.hypot(np.diff(x), np.diff(y))
    ok = (t[:-1] >= t_from) & np.isfinite(step) & (dt > 0)
    if live is not None:
        live = np.asarray(live, dtype=bool)
        ok &= live[:-1] & live[1:]
    if not ok.any():
        return math.nan
    return float(np.mean(step[ok] < STILL_SPEED_M_S * dt[ok]))


def speedup(tick_t: np.ndarray, tick_log_ns: np.ndarray) -> float:
    """Simulated time per wall time over the recorded ticks."""
    tick_t = np.asarray(tick_t, dtype=float)
    tick_log_ns = np.asarray(tick_log_ns)
    if tick_t.size < 2:
        return math.nan
    wall = float(tick_log_ns.max() - tick_log_ns.min()) / 1e9
    sim = float(tick_t.max() - tick_t.min())
    return sim / wall if wall > 0 else math.nan


# a team's measures ------------------------------------------------------------------
@dataclass
class TeamErrors:
    """Error time series of a team on one time grid: per neighbour pair (rows) against
    time (columns), NaN where the pair is not neighbours or a value is unknown."""

    t: np.ndarray  # time of each sample, s
    pairs: list[tuple[int, int]]  # neighbour pairs (ids of live robots next to each other)
    phase: np.ndarray  # e_phi with the position-based phase (eq. 3.1), rad
    phase_path: np.ndarray  # e_phi with the path-length phase, rad
    workload: np.ndarray  # e_Psi with the true workload (true patrol depth), m^2
    workload_agents: np.ndarray  # e_Psi from the workloads the agents published, m^2
    # e_phi from the phases the agents published (each from its own pose estimate), rad:
    # the errors as the robots see them, how the thesis measured its robot runs
    phase_agents: np.ndarray
    ids: list[int] = field(default_factory=list)  # the robots, in id order
    live: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))


def _path_phase_of_known(x: np.ndarray, y: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """``path_length_phase`` over the samples with a known position and direction."""
    known = np.isfinite(x) & np.isfinite(y) & np.isfinite(direction)
    out = np.full(x.shape, np.nan)
    out[known] = path_length_phase(x[known], y[known], direction[known])
    return out


def team_errors(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    direction: np.ndarray,
    seen_phase: np.ndarray,
    seen_workload: np.ndarray,
    edge: EdgeModel,
    live: np.ndarray | None = None,
    ids: Sequence[int] | None = None,
    phase_path: np.ndarray | None = None,
) -> TeamErrors:
    """Phase and workload errors of neighbour pairs (``active_pairs`` on ``live``;
    None: always live) from arrays of shape (robots, samples), robots in id order
    (``ids``, default 0..n-1): position phase (eq. 3.1) from the true x, lo, hi and
    direction; path-length phase from x, y and direction (or ``phase_path`` given per
    robot); true workload from the edge's depth profile; and the phases and workloads
    the agents published."""
    x, y, lo, hi, direction, seen_phase, seen_workload = (
        np.atleast_2d(np.asarray(v, dtype=float))
        for v in (x, y, lo, hi, direction, seen_phase, seen_workload)
    )
    t = np.asarray(t, dtype=float)
    n = x.shape[0]
    robots = list(range(n)) if ids is None else list(ids)
    alive = np.ones(x.shape, dtype=bool) if live is None else np.asarray(live, dtype=bool)
    index_pairs, active = active_pairs(list(range(n)), alive)
    if phase_path is None:
        phase_path = np.vstack([_path_phase_of_known(x[j], y[j], direction[j])
                                for j in range(n)]) if n else x.copy()

    def errors(values: np.ndarray, wrap: bool) -> np.ndarray:
        if not index_pairs:
            return np.empty((0, t.size))
        rows = {j: values[j] for j in range(n)}
        return np.where(active, pair_errors(rows, index_pairs, wrap), np.nan)

    return TeamErrors(
        t=t,
        pairs=[(robots[a], robots[b]) for a, b in index_pairs],
        phase=errors(position_phase(x, lo, hi, direction), True),
        phase_path=errors(np.asarray(phase_path, dtype=float), True),
        workload=errors(edge.workload(lo, hi, t), False),
        workload_agents=errors(seen_workload, False),
        phase_agents=errors(seen_phase, True),
        ids=robots,
        live=alive,
    )


def mean_workload(t: np.ndarray, live: np.ndarray, total_workload: float | np.ndarray,
                  last: float = STEADY_LAST) -> float:
    """Mean workload per robot over the last ``last`` of the run: the edge's total true
    workload (one number, or one per sample on a map that changes) over the number of
    live robots, averaged over the samples."""
    live = np.asarray(live, dtype=bool)
    team = live.sum(axis=0) if live.size else np.zeros(np.asarray(t).size)
    sel = window_mask(t, 1.0 - last, 1.0) & (team > 0)
    if not sel.any():
        return math.nan
    if np.ndim(total_workload):
        return float(np.mean(np.asarray(total_workload)[sel] / team[sel]))
    return float(np.mean(total_workload / team[sel]))


def change_recovery(
    errors: TeamErrors,
    edge: EdgeModel,
    cycle_s: np.ndarray,
    band_rel: float = WORKLOAD_REL_BAND,
    smooth_s: float = CONVERGE_SMOOTH_S,
) -> list[dict[str, float]]:
    """How the team rebalanced after each change of the map (``edge.changes``): the
    workload band at the change's end (``band_rel`` of the mean true workload per live
    robot then), the team's cycle then (the median of the cycles the live agents
    followed, ``cycle_s`` of shape (robots, samples)), and from the change's end (up to
    the next change's start, or the run's end) the time until max-over-pairs |e_Psi|,
    averaged over the trailing ``smooth_s``, is first back in the band (``back_s``,
    0 if it never left) and after which it stays there (``settled_s``), each also in
    cycles; ``peak_rel`` its largest from the change's start, and ``during_rel`` the
    mean |e_Psi| over the pairs and the window, both over the mean workload. NaN where
    not measurable (never back, no sample after the change)."""
    t = errors.t
    worst = running_mean(t, max_over_pairs(errors.workload), smooth_s)
    live = np.asarray(errors.live, dtype=bool)
    team = live.sum(axis=0) if live.size else np.zeros(t.size)
    total = np.broadcast_to(np.asarray(edge.total_workload_at(t), dtype=float), t.shape)
    cycle = np.where(live, np.asarray(cycle_s, dtype=float), np.nan) if live.size else live
    changes = edge.changes
    out = []
    for i, (t0, t1) in enumerate(changes):
        until = changes[i + 1][0] if i + 1 < len(changes) else math.inf
        after = np.flatnonzero((t >= t1 - 1e-9) & (t < until))
        row = {"t0": t0, "t1": t1, "band_m2": math.nan, "cycle_s": math.nan,
               "back_s": math.nan, "back_cycles": math.nan, "settled_s": math.nan,
               "settled_cycles": math.nan, "peak_rel": math.nan, "during_rel": math.nan}
        out.append(row)
        if after.size == 0 or team[after[0]] == 0:
            continue
        k1 = after[0]
        mean = float(total[k1] / team[k1])
        band = band_rel * mean
        cycles = cycle[:, k1][np.isfinite(cycle[:, k1]) & (cycle[:, k1] > 0)]
        period = float(np.median(cycles)) if cycles.size else math.nan
        known = after[np.isfinite(worst[after])]
        inside = worst[known] <= band
        back = float(t[known[inside][0]] - t1) if inside.any() else math.nan
        outside = known[~inside]
        if outside.size == 0:
            settled = 0.0 if known.size else math.nan
        else:
            later = known[known > outside[-1]]
            settled = float(t[later[0]] - t1) if later.size else math.nan
        window = (t >= t0) & (t <= t1)
        since = (t >= t0) & (t < until)
        per = np.where(team > 0, total / np.maximum(team, 1), np.nan)
        rel = np.abs(np.asarray(errors.workload, dtype=float)[:, window]) / per[window]
        row.update(band_m2=band, cycle_s=period, back_s=back, back_cycles=back / period,
                   settled_s=settled, settled_cycles=settled / period,
                   peak_rel=nanmax(worst[since] / per[since]), during_rel=nanmean(rel))
    return out


def error_measures(
    errors: TeamErrors,
    total_workload: float | np.ndarray,
    last: float = STEADY_LAST,
    phase_band: float = PHASE_BAND_RAD,
    workload_band: float = WORKLOAD_BAND_M2,
    smooth_s: float = CONVERGE_SMOOTH_S,
) -> dict[str, float]:
    """The error keys of ``team_measures`` from a team's error series: steady state
    (``steady_state``: mean and max of |e| over pairs and the last ``last``) of both
    phases, of the true workload absolute and relative to the mean workload per robot,
    and of the agents' own view; times to converge into the bands."""
    t = errors.t
    phase_sse, phase_max = steady_state(t, errors.phase, last)
    path_sse, path_max = steady_state(t, errors.phase_path, last)
    work_sse, work_max = steady_state(t, errors.workload, last)
    agents_phase_sse, agents_phase_max = steady_state(t, errors.phase_agents, last)
    agents_work_sse, agents_work_max = steady_state(t, errors.workload_agents, last)
    mean = mean_workload(t, errors.live, total_workload, last)
    phase_conv = converge_time(t, errors.phase, phase_band, smooth_s)
    work_conv = converge_time(t, errors.workload, workload_band, smooth_s)
    rel_conv = (converge_time(t, errors.workload, WORKLOAD_REL_BAND * mean, smooth_s)
                if mean > 0 else math.nan)
    later = (max(phase_conv, work_conv)
             if math.isfinite(phase_conv) and math.isfinite(work_conv) else math.nan)

    def relative(value: float) -> float:
        return value / mean if mean > 0 else math.nan

    return {
        "phase_sse_rad": phase_sse,
        "phase_max_rad": phase_max,
        "phase_path_sse_rad": path_sse,
        "phase_path_max_rad": path_max,
        "workload_sse_m2": work_sse,
        "workload_max_m2": work_max,
        "workload_mean_m2": mean,
        "workload_rel_sse": relative(work_sse),
        "workload_rel_max": relative(work_max),
        "phase_sse_agents_rad": agents_phase_sse,
        "phase_max_agents_rad": agents_phase_max,
        "workload_sse_agents_m2": agents_work_sse,
        "workload_max_agents_m2": agents_work_max,
        "workload_rel_sse_agents": relative(agents_work_sse),
        "phase_converge_s": phase_conv,
        "workload_converge_s": work_conv,
        "workload_rel_converge_s": rel_conv,
        "converge_s": later,
    }


def team_measures(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    direction: np.ndarray,
    seen_phase: np.ndarray,
    seen_workload: np.ndarray,
    edge: EdgeModel,
    live: np.ndarray | None = None,
    last: float = STEADY_LAST,
) -> dict[str, float]:
    """Every measure of a team's run, from arrays of shape (robots, ticks) on the time
    grid ``t``, robots in id order, neighbours consecutive ids (a chain); ``live``
    (bool, same shape) marks the ticks a robot was in the team (None: always). x, y:
    true positions; lo, hi, direction: each robot's segment and direction of travel;
    seen_phase, seen_workload: what the agents published. Errors and their steady
    state over the last ``last`` of the run (``error_measures``), revisit times over
    the second half (``idleness_measures``, visits of the local edge of ``edge``),
    and ``still_frac_max``: the largest fraction of steady-state ticks a robot stood
    still (``still_fraction``). A flat dict of floats, NaN where not measurable."""
    t = np.asarray(t, dtype=float)
    x, y, direction = (np.atleast_2d(np.asarray(v, dtype=float)) for v in (x, y, direction))
    alive = np.ones(x.shape, dtype=bool) if live is None else np.asarray(live, dtype=bool)
    errors = team_errors(t, x, y, lo, hi, direction, seen_phase, seen_workload, edge, alive)
    out = error_measures(errors, edge.total_workload_at(t), last)
    if t.size < 2:
        nothing = idleness_measures([], math.nan, math.nan, math.nan, edge.length)
        return {**out, **nothing, "still_frac_max": math.nan}
    # a robot out of the team neither visits nor sweeps
    x_live, y_live = np.where(alive, x, np.nan), np.where(alive, y, np.nan)
    t_from, t_to = revisit_window(t)
    tracks = [(t, x_live[j], y_live[j], t, direction[j]) for j in range(x.shape[0])]
    _, gaps, worst = visit_gaps(tracks, edge, t_from, t_to)
    rate = sweep_rate([(t, x_live[j]) for j in range(x.shape[0])], t_from, t_to,
                      [(t, direction[j]) for j in range(x.shape[0])])
    out.update(idleness_measures(gaps, t_from, t_to, rate, edge.length,
                                 worst_per_point=worst))
    still_from = float(t[0] + (1.0 - last) * (t[-1] - t[0]))
    still = [still_fraction(t, x[j], y[j], still_from, alive[j]) for j in range(x.shape[0])]
    out["still_frac_max"] = nanmax(np.asarray(still))
    return out
