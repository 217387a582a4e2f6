"""The measures every report prints (DESIGN.md "Measures"): pure functions over arrays.

Phase (thesis eq. 3.1, with the case condition read as the direction of travel),
phase and workload errors per neighbour pair (eq. 3.2, 3.3), steady-state error,
time to converge, revisit time along the edge, speed-up. No I/O, no clock.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

TWO_PI = 2.0 * math.pi


def wrap_pi(angle: np.ndarray | float) -> np.ndarray:
    """Angles wrapped to (-pi, pi]."""
    a = np.asarray(angle, dtype=float)
    return a - TWO_PI * np.ceil((a - math.pi) / TWO_PI)


def wrap_2pi(angle: np.ndarray | float) -> np.ndarray:
    """Angles wrapped to [0, 2 pi)."""
    a = np.mod(np.asarray(angle, dtype=float), TWO_PI)
    return np.where(a >= TWO_PI, 0.0, a)


def position_phase(
    x: np.ndarray | float,
    lo: np.ndarray | float,
    hi: np.ndarray | float,
    direction: np.ndarray | float,
) -> np.ndarray:
    """Position-based phase, thesis eq. 3.1 with the case on the direction of travel:
    pi (x - lo) / (hi - lo) towards hi (+1), pi (hi - x) / (hi - lo) + pi towards lo;
    x clipped into [lo, hi], result in [0, 2 pi)."""
    x, lo, hi, direction = (np.asarray(v, dtype=float) for v in (x, lo, hi, direction))
    width = hi - lo
    xc = np.clip(x, lo, hi)
    towards_hi = math.pi * (xc - lo) / width
    towards_lo = math.pi * (hi - xc) / width + math.pi
    return wrap_2pi(np.where(direction >= 0, towards_hi, towards_lo))


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


def crossings(t: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Times and x positions where a track crosses the edge line y = 0 (interpolated)."""
    t, x, y = (np.asarray(v, dtype=float) for v in (t, x, y))
    if t.size < 2:
        return np.empty(0), np.empty(0)
    side = y >= 0
    k = np.flatnonzero(side[:-1] != side[1:])
    y0, y1 = y[k], y[k + 1]
    frac = np.where(y1 != y0, y0 / (y0 - y1), 0.0)
    return t[k] + frac * (t[k + 1] - t[k]), x[k] + frac * (x[k + 1] - x[k])


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
    visit_t = np.asarray(visit_t, dtype=float)
    visit_x = np.asarray(visit_x, dtype=float)
    order = np.argsort(visit_t, kind="stable")
    visit_t, visit_x = visit_t[order], visit_x[order]
    groups = None if visit_group is None else np.asarray(visit_group)[order]
    out: list[np.ndarray | None] = []
    for p in np.asarray(points, dtype=float):
        near = np.abs(visit_x - p) <= radius
        times = visit_t[near]
        if groups is not None and times.size:
            _, first = np.unique(groups[near], return_index=True)
            times = np.sort(times[first])
        times = merge_visits(times, merge_s)
        times = times[(times >= t_from) & (times <= t_to)]
        out.append(np.diff(times) if times.size >= 2 else None)
    return out


def revisit_profile(
    gaps: Sequence[np.ndarray | None], t_from: float, t_to: float
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and worst revisit time of each point; a point seen fewer than twice in the
    window has no mean (NaN) and the whole window as its worst."""
    mean = np.array([float(g.mean()) if g is not None else math.nan for g in gaps])
    worst = np.array([float(g.max()) if g is not None else t_to - t_from for g in gaps])
    return mean, worst


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
    gaps: Sequence[np.ndarray | None], t_from: float, t_to: float
) -> tuple[float, float]:
    """Mean over every interval of every point, and the worst point's worst."""
    known = [g for g in gaps if g is not None]
    pooled = np.concatenate(known) if known else np.empty(0)
    _, worst = revisit_profile(gaps, t_from, t_to)
    return nanmean(pooled), nanmax(worst)


def edge_points(edge_lo: float, edge_hi: float, step: float = 0.1) -> np.ndarray:
    """Points every ``step`` metres over [edge_lo, edge_hi], both ends included."""
    n = int(math.floor((edge_hi - edge_lo) / step + 1e-9))
    return edge_lo + step * np.arange(n + 1)


def sweep_rate(
    tracks: Sequence[tuple[np.ndarray, np.ndarray]], t_from: float, t_to: float
) -> float:
    """Team along-edge sweep rate: sum over robots of |dx| in [t_from, t_to] / duration.
    ``tracks`` holds one (t, x) per robot."""
    duration = t_to - t_from
    if duration <= 0:
        return math.nan
    total = 0.0
    for t, x in tracks:
        t = np.asarray(t, dtype=float)
        x = np.asarray(x, dtype=float)
        sel = (t >= t_from) & (t <= t_to)
        if sel.sum() >= 2:
            total += float(np.abs(np.diff(x[sel])).sum())
    return total / duration


def ideal_revisit(edge_length: float, team_sweep_rate: float) -> float:
    """Revisit time of an ideal team with the same along-edge speed: L / sweep rate."""
    if not team_sweep_rate > 0:
        return math.nan
    return edge_length / team_sweep_rate


def speedup(tick_t: np.ndarray, tick_log_ns: np.ndarray) -> float:
    """Simulated time per wall time over the recorded ticks."""
    tick_t = np.asarray(tick_t, dtype=float)
    tick_log_ns = np.asarray(tick_log_ns)
    if tick_t.size < 2:
        return math.nan
    wall = float(tick_log_ns.max() - tick_log_ns.min()) / 1e9
    sim = float(tick_t.max() - tick_t.min())
    return sim / wall if wall > 0 else math.nan
