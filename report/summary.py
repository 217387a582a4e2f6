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
from report.measures import (
    CONVERGE_SMOOTH_S,
    PHASE_BAND_RAD,
    STEADY_LAST,
    WORKLOAD_BAND_M2,
)
from report.measures import POINT_STEP_M as POINT_STEP_M  # re-exported: the report's grids
from report.measures import VISIT_MERGE_S as VISIT_MERGE_S
from report.series import ErrorSeries, RunTable, edge_model, run_table

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
    "phase_sse_path_rad",  # the same as phase_path_sse_rad, the key older summaries have
    "phase_max_rad",
    "phase_path_sse_rad",
    "phase_path_max_rad",
    "workload_sse_m2",
    "workload_max_m2",
    "workload_mean_m2",
    "workload_rel_sse",
    "workload_rel_max",
    "converge_s",
    "phase_converge_s",
    "workload_converge_s",
    "workload_rel_converge_s",
    "revisit_mean_s",
    "revisit_std_s",
    "revisit_worst_s",
    "revisit_ideal_s",
    "revisit_optimum_s",
    "revisit_worst_ratio",
    "still_frac_max",
    "phase_q1_rad",
    "phase_q4_rad",
    "workload_q1_m2",
    "workload_q4_m2",
    "ticks",
    "ticks_expected",
    "recording_complete",
    "recording_note",
    "invalid_messages",
    "rejected_messages",
    "refused",
    "coverage_gap_m_s",
    "faults",
    "loc_error_mean_m",
    "loc_error_p95_m",
    "phase_sse_agents_rad",
    "phase_max_agents_rad",
    "workload_sse_agents_m2",
    "workload_max_agents_m2",
    "workload_rel_sse_agents",
    "positions_from",
    "change",
    "changes",
)

# The goals every report is held to (DESIGN.md "Beyond the thesis's scenarios"): the
# key, what it is, and the bound it must stay below.
GOALS = (
    ("phase_sse_rad", "phase steady-state error, position-based (rad)", 0.05),
    ("phase_path_sse_rad", "phase steady-state error, path length (rad)", 0.15),
    ("workload_rel_sse", "workload steady-state error / mean workload", 0.005),
    ("revisit_worst_ratio", "worst revisit / partition optimum", 1.3),
    ("still_frac_max", "fraction of the last quarter a robot stood still, worst robot", 0.2),
)


def goals_met(summary: dict[str, Any]) -> list[tuple[str, str, Any, float, bool | None]]:
    """Each goal as (key, what, value, bound, met); met is None where the run has no
    value for it."""
    out: list[tuple[str, str, Any, float, bool | None]] = []
    for key, label, bound in GOALS:
        value = summary.get(key)
        met = (value < bound if isinstance(value, (int, float)) and math.isfinite(value)
               else None)
        out.append((key, label, value, bound, met))
    return out


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


@dataclass
class Revisit:
    """Revisit times along the edge over the second half of the run."""

    points: np.ndarray  # positions along the edge, every POINT_STEP_M
    gaps: list[np.ndarray | None]  # per point, the times between its visits
    t_from: float
    t_to: float
    sweep_rate: float  # the team's along-edge sweep rate n v over the window, m/s
    edge_length: float  # m, along x
    worst: np.ndarray | None = None  # per point, its worst idleness over the window

    @property
    def ideal_s(self) -> float:
        """Mean revisit time of an ideal team of this sweep rate, L / (n v)."""
        return m.ideal_revisit(self.edge_length, self.sweep_rate)

    @property
    def optimum_s(self) -> float:
        """Worst revisit time of the optimal partitioned patrol, 2 L / (n v)."""
        return m.partition_optimum(self.edge_length, self.sweep_rate)

    def profile(self) -> tuple[np.ndarray, np.ndarray]:
        return m.revisit_profile(self.gaps, self.t_from, self.t_to, self.worst)

    def pooled(self) -> tuple[float, float]:
        return m.pooled_revisit(self.gaps, self.t_from, self.t_to, self.worst)

    def measures(self) -> dict[str, float]:
        """The revisit keys of the summary (``measures.idleness_measures``)."""
        return m.idleness_measures(self.gaps, self.t_from, self.t_to, self.sweep_rate,
                                   self.edge_length, worst_per_point=self.worst)


NO_REVISIT = m.idleness_measures([], math.nan, math.nan, math.nan, math.nan)


def revisit(run: RunData, t: np.ndarray) -> Revisit | None:
    """Revisit times of points every 0.1 m along the edge, over the second half of the
    run: visits are crossings of the local edge (the recording's edge shape), one per
    robot sweep. None without positions, edge or time."""
    tracks, edge = run.positions, edge_model(run)
    if t.size < 2 or not tracks or edge is None:
        return None
    t_from, t_to = m.revisit_window(t)
    no_states = np.empty(0)
    per_robot = []
    for rid, tr in tracks.items():
        st = run.states.get(rid)
        sweeps = (st.t, st.direction) if st is not None else (no_states, no_states)
        per_robot.append((tr.t, tr.x, tr.y, *sweeps))
    points, gaps, worst = m.visit_gaps(per_robot, edge, t_from, t_to)
    rate = m.sweep_rate([(tr.t, tr.x) for tr in tracks.values()], t_from, t_to,
                        [(r[3], r[4]) for r in per_robot])
    return Revisit(points, gaps, t_from, t_to, rate, edge.length, worst)


def still_frac_max(run: RunData, s: ErrorSeries, last: float = STEADY_LAST) -> float:
    """The largest fraction of the last quarter a robot stood still
    (``measures.still_fraction``), on each track as recorded, while in the team."""
    if s.t.size < 2:
        return math.nan
    t_from = float(s.t[0] + (1.0 - last) * (s.t[-1] - s.t[0]))
    fractions = []
    for j, rid in enumerate(s.ids):
        tr = run.positions.get(rid)
        if tr is not None:
            live = m.hold(s.t, s.live[j].astype(float), tr.t) > 0.5
            fractions.append(m.still_fraction(tr.t, tr.x, tr.y, t_from, live))
    return m.nanmax(np.asarray(fractions))


def _integral(t: np.ndarray, values: np.ndarray) -> float:
    """Integral over time of a per-tick value held until the next tick (NaN as 0)."""
    if t.size < 2:
        return 0.0
    return float(np.sum(np.nan_to_num(values[:-1]) * np.diff(t)))


def compute_summary(
    run: RunData | RunTable,
    phase_band: float = PHASE_BAND_RAD,
    workload_band: float = WORKLOAD_BAND_M2,
    rev: Revisit | None = None,
    loc: LocErrors | None = None,
) -> dict[str, Any]:
    """Every measure of the run (or of its table, ``run_table``, if already built),
    keyed as in ``KEYS`` (NaN where it cannot be computed). The team's measures are
    those of ``measures.team_measures``, by the same functions. ``rev`` and ``loc``:
    the run's revisit times and localisation errors, if already computed."""
    table = run if isinstance(run, RunTable) else run_table(run)
    run, s = table.run, table.errors
    loc_mean, loc_p95 = summary_stats((loc or localization_errors(run)).pooled("pf"))
    info = run.info
    edge = table.edge
    errors = m.error_measures(s, edge.total_workload_at(s.t) if edge else math.nan, STEADY_LAST,
                              phase_band, workload_band, CONVERGE_SMOOTH_S)
    rev = rev or revisit(run, table.t)
    gap, _ = coverage(table)
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
        **errors,
        "phase_sse_path_rad": errors["phase_path_sse_rad"],
        **(rev.measures() if rev else NO_REVISIT),
        "still_frac_max": still_frac_max(run, s),
        "phase_q1_rad": m.window_abs(s.t, s.phase, 0.0, 0.25)[0],
        "phase_q4_rad": m.window_abs(s.t, s.phase, 0.75, 1.0)[0],
        "workload_q1_m2": m.window_abs(s.t, s.workload, 0.0, 0.25)[0],
        "workload_q4_m2": m.window_abs(s.t, s.workload, 0.75, 1.0)[0],
        "ticks": int(run.tick_t.size),
        **recording_completeness(run),
        "invalid_messages": int(run.invalid),
        "rejected_messages": rejected_messages(run),
        "refused": run.refused,
        "coverage_gap_m_s": _integral(s.t, gap),
        "faults": fault_measures(run, s, gap, workload_band, CONVERGE_SMOOTH_S),
        "loc_error_mean_m": loc_mean,
        "loc_error_p95_m": loc_p95,
        # "truth", or "poses" for a recording without ground truth (hardware)
        "positions_from": run.positions_from,
        # a map that changes: the changes as given, and how the team rebalanced after each
        "change": info.get("change", ""),
        "changes": m.change_recovery(s, edge, table.cycle) if edge is not None else [],
    }
    assert set(out) == set(KEYS), set(out) ^ set(KEYS)
    return json_safe({key: out[key] for key in KEYS})


def rejected_messages(run: RunData) -> int:
    """Well-formed messages refused as implausible by the recorder, agents and world."""
    return (sum(run.rejected.values()) + sum(run.refused.get("agents_rejected", {}).values())
            + int(run.refused.get("world_rejected", 0)))


def recording_completeness(run: RunData) -> dict[str, Any]:
    """Whether the recording holds the whole run: its file is whole (``cut_short``) and
    it has every tick the run was to have (its duration over its tick, from WorldInfo).
    ``recording_note`` says what is missing, "" for nothing."""
    info = run.info
    expected = None
    if info.get("duration_s") and info.get("dt"):
        expected = int(round(float(info["duration_s"]) / float(info["dt"])))
    ticks = int(run.tick_t.size)
    notes = []
    if run.cut_short:
        last = f"t = {run.tick_t[-1]:.1f} s" if ticks else "no tick"
        notes.append(f"cut short: {run.cut_short}; it holds the run up to {last}")
    if expected is not None and ticks < expected:
        notes.append(f"{ticks} of the run's {expected} ticks recorded")
    return {"ticks_expected": expected, "recording_complete": not notes,
            "recording_note": "; ".join(notes)}


def write_summary(path: str | Path, summary: dict[str, Any]) -> None:
    Path(path).write_text(json.dumps(json_safe(summary), indent=2, allow_nan=False) + "\n")
