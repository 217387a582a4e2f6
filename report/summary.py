"""summary.json: the run's parameters and its measures, JSON-safe (NaN becomes null)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from report import measures as m
from report.faults import coverage, fault_measures
from report.load import RunData
from report.localization import LocErrors, localization_errors, summary_stats
from report.series import ErrorSeries, error_series, time_grid

PHASE_BAND_RAD = 0.15
WORKLOAD_BAND_M2 = 0.05
VISIT_MERGE_S = 1.0
CONVERGE_SMOOTH_S = 10.0  # converge on |e| averaged over about two patrol passes
POINT_STEP_M = 0.1

KEYS = (
    "map",
    "start",
    "robots",
    "localization",
    "seed",
    "duration_s",
    "odom_noise",
    "odom_turn_noise",
    "speedup",
    "phase_sse_rad",
    "phase_sse_path_rad",
    "phase_max_rad",
    "workload_sse_m2",
    "workload_max_m2",
    "converge_s",
    "phase_converge_s",
    "workload_converge_s",
    "revisit_mean_s",
    "revisit_worst_s",
    "revisit_ideal_s",
    "phase_q1_rad",
    "phase_q4_rad",
    "workload_q1_m2",
    "workload_q4_m2",
    "ticks",
    "invalid_messages",
    "coverage_gap_m_s",
    "faults",
    "loc_error_mean_m",
    "loc_error_p95_m",
    "phase_sse_agents_rad",
    "workload_sse_agents_m2",
    "positions_from",
)


def json_safe(value: Any) -> Any:
    """``value`` with NaN/inf as None and numpy scalars as Python numbers."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _later(a: float, b: float) -> float:
    return max(a, b) if math.isfinite(a) and math.isfinite(b) else math.nan


def sweep_index(run: RunData, rid: int, at_t: np.ndarray) -> np.ndarray:
    """Which sweep of robot ``rid`` (count of its reversals so far) each time falls in."""
    st = run.states.get(rid)
    if st is None or st.t.size == 0:
        return np.zeros(np.asarray(at_t).size, dtype=np.int64)
    reversals = np.concatenate([[0], np.cumsum(np.diff(st.direction) != 0)])
    idx = np.clip(np.searchsorted(st.t, at_t, side="right") - 1, 0, st.t.size - 1)
    return reversals[idx].astype(np.int64)


@dataclass
class Revisit:
    """Revisit times along the edge over the second half of the run."""

    points: np.ndarray  # positions along the edge, every POINT_STEP_M
    gaps: list[np.ndarray | None]  # per point, the times between its visits
    t_from: float
    t_to: float
    ideal_s: float

    def profile(self) -> tuple[np.ndarray, np.ndarray]:
        return m.revisit_profile(self.gaps, self.t_from, self.t_to)

    def pooled(self) -> tuple[float, float]:
        return m.pooled_revisit(self.gaps, self.t_from, self.t_to)


def revisit(run: RunData, t: np.ndarray) -> Revisit | None:
    """Revisit times of points every 0.1 m along the edge, over the second half of the
    run; one visit per robot sweep. None without positions, edge or time."""
    tracks, edge = run.positions, run.edge
    if t.size < 2 or not tracks or edge is None:
        return None
    t_from, t_to = float(t[0] + 0.5 * (t[-1] - t[0])), float(t[-1])
    edge_lo, edge_hi = edge
    radius = float(run.info.get("robot_radius", 0.17))
    visit_t, visit_x, visit_group = [], [], []
    for rid, tr in tracks.items():
        tc, xc = m.crossings(tr.t, tr.x, tr.y)
        visit_t.append(tc)
        visit_x.append(xc)
        visit_group.append(rid * 1_000_000 + sweep_index(run, rid, tc))
    points = m.edge_points(edge_lo, edge_hi, POINT_STEP_M)
    gaps = m.point_gaps(
        points,
        np.concatenate(visit_t),
        np.concatenate(visit_x),
        radius,
        t_from,
        t_to,
        VISIT_MERGE_S,
        np.concatenate(visit_group),
    )
    rate = m.sweep_rate([(tr.t, tr.x) for tr in tracks.values()], t_from, t_to)
    return Revisit(points, gaps, t_from, t_to, m.ideal_revisit(edge_hi - edge_lo, rate))


def _integral(t: np.ndarray, values: np.ndarray) -> float:
    """Integral over time of a per-tick value held until the next tick (NaN as 0)."""
    if t.size < 2:
        return 0.0
    return float(np.sum(np.nan_to_num(values[:-1]) * np.diff(t)))


def compute_summary(
    run: RunData,
    series: ErrorSeries | None = None,
    phase_band: float = PHASE_BAND_RAD,
    workload_band: float = WORKLOAD_BAND_M2,
    rev: Revisit | None = None,
    loc: LocErrors | None = None,
) -> dict[str, Any]:
    """Every measure of the run, keyed as in ``KEYS`` (NaN where it cannot be computed).
    ``rev``: the run's revisit times, if already computed."""
    s = error_series(run) if series is None else series
    loc_mean, loc_p95 = summary_stats((loc or localization_errors(run)).pooled("pf"))
    info = run.info
    phase_sse, phase_max = m.steady_state(s.t, s.phase)
    path_sse, _ = m.steady_state(s.t, s.phase_path)
    work_sse, work_max = m.steady_state(s.t, s.workload)
    phase_conv = m.converge_time(s.t, s.phase, phase_band, CONVERGE_SMOOTH_S)
    work_conv = m.converge_time(s.t, s.workload, workload_band, CONVERGE_SMOOTH_S)
    rev = rev or revisit(run, time_grid(run))
    gap, _ = coverage(run, s.t)
    rev_mean, rev_worst = rev.pooled() if rev else (math.nan, math.nan)
    rev_ideal = rev.ideal_s if rev else math.nan
    out: dict[str, Any] = {
        "map": info.get("map"),
        "start": info.get("start"),
        "robots": info.get("robots", len(run.robot_ids)),
        "localization": info.get("localization"),
        "seed": info.get("seed"),
        "duration_s": info.get("duration_s"),
        "odom_noise": info.get("odom_noise"),
        "odom_turn_noise": info.get("odom_turn_noise"),
        "speedup": m.speedup(run.tick_t, run.tick_log_ns),
        "phase_sse_rad": phase_sse,
        "phase_sse_path_rad": path_sse,
        "phase_max_rad": phase_max,
        "workload_sse_m2": work_sse,
        "workload_max_m2": work_max,
        "converge_s": _later(phase_conv, work_conv),
        "phase_converge_s": phase_conv,
        "workload_converge_s": work_conv,
        "revisit_mean_s": rev_mean,
        "revisit_worst_s": rev_worst,
        "revisit_ideal_s": rev_ideal,
        "phase_q1_rad": m.window_abs(s.t, s.phase, 0.0, 0.25)[0],
        "phase_q4_rad": m.window_abs(s.t, s.phase, 0.75, 1.0)[0],
        "workload_q1_m2": m.window_abs(s.t, s.workload, 0.0, 0.25)[0],
        "workload_q4_m2": m.window_abs(s.t, s.workload, 0.75, 1.0)[0],
        "ticks": int(run.tick_t.size),
        "invalid_messages": int(run.invalid),
        "coverage_gap_m_s": _integral(s.t, gap),
        "faults": fault_measures(run, s, gap, workload_band, CONVERGE_SMOOTH_S),
        "loc_error_mean_m": loc_mean,
        "loc_error_p95_m": loc_p95,
        # as the robots see it: from the phases and workloads they published
        "phase_sse_agents_rad": m.steady_state(s.t, s.phase_agents)[0],
        "workload_sse_agents_m2": m.steady_state(s.t, s.workload_agents)[0],
        # "truth", or "poses" for a recording without ground truth (hardware)
        "positions_from": run.positions_from,
    }
    assert tuple(out) == KEYS
    return json_safe(out)


def write_summary(path: str | Path, summary: dict[str, Any]) -> None:
    Path(path).write_text(json.dumps(json_safe(summary), indent=2, allow_nan=False) + "\n")
