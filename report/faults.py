"""Measures of a run with faults (agents killed, frozen, restarted, joining): coverage
of the edge by the live agents' segments at every tick, and for each fault when the
team noticed it, how much edge went unowned meanwhile and when the workload was
balanced again. Pure: a loaded recording in, numbers out."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from report import measures as m
from report.load import RunData
from report.series import ErrorSeries, RunTable

GONE = ("kill", "freeze")  # faults after which the agent should be dropped
BACK = ("restart", "thaw", "join")  # and those after which it should be taken back


def segment_union(lo: np.ndarray, hi: np.ndarray, edge_lo: float, edge_hi: float
                  ) -> tuple[float, float]:
    """Length of [edge_lo, edge_hi] covered by no segment, and the length covered
    more than once (segments' total length minus their union)."""
    ok = np.isfinite(lo) & np.isfinite(hi) & (hi > lo)
    lo, hi = np.clip(lo[ok], edge_lo, edge_hi), np.clip(hi[ok], edge_lo, edge_hi)
    order = np.argsort(lo)
    covered, reach = 0.0, edge_lo
    for a, b in zip(lo[order], hi[order], strict=True):
        if b > reach:
            covered += b - max(a, reach)
            reach = b
    total = float(np.sum(hi - lo))
    return (edge_hi - edge_lo) - covered, max(0.0, total - covered)


def coverage(table: RunTable) -> tuple[np.ndarray, np.ndarray]:
    """Gap and overlap (m) of the live agents' segments at each tick of the run's table."""
    t, run = table.t, table.run
    gap, overlap = np.full(t.size, np.nan), np.full(t.size, np.nan)
    if not table.ids or run.edge is None:
        return gap, overlap
    edge_lo, edge_hi = run.edge
    lo, hi = table.live_segments()
    for k in range(t.size):
        gap[k], overlap[k] = segment_union(lo[:, k], hi[:, k], edge_lo, edge_hi)
    return gap, overlap


def detection_time(run: RunData, fault: dict[str, Any]) -> float:
    """Simulated time at which the team had noticed ``fault``: after a kill or a
    freeze, the first state of another agent, from the fault on, that names no agent
    as neighbour which is the faulty one while some agent still did just before;
    after a restart, a thaw or a join, the first state of another agent naming it."""
    agent, at = int(fault["agent"]), float(fault["t"])
    times, names = [], []
    for rid, st in run.states.items():
        if rid == agent:
            continue
        sel = st.t >= at
        times.append(st.t[sel])
        names.append((st.lower[sel] == agent) | (st.upper[sel] == agent))
    if not times:
        return math.nan
    t = np.concatenate(times)
    named = np.concatenate(names)
    order = np.argsort(t, kind="stable")
    t, named = t[order], named[order]
    if fault["kind"] in BACK:
        hit = np.flatnonzero(named)
        return float(t[hit[0]]) if hit.size else math.nan
    # gone: the first tick at which no other agent names it any more
    ticks = np.unique(t)
    still = np.zeros(ticks.size, dtype=bool)
    np.logical_or.at(still, np.searchsorted(ticks, t), named)
    free = np.flatnonzero(~still)
    return float(ticks[free[0]]) if free.size else math.nan


def fault_measures(run: RunData, series: ErrorSeries, gap: np.ndarray, band: float,
                   smooth_s: float) -> list[dict[str, Any]]:
    """One object per fault: kind, agent, at_s, detected_s (when the team noticed,
    simulated time), detection_s (how long that took), detection_wall_s (the same in
    wall time, which is what a lease costs when the simulation is lockstep),
    coverage_gap_m_s (edge owned by no live agent, integrated from the fault to the
    next one), rebalanced_s (how long after the fault the worst workload error over
    neighbour pairs, averaged over ``smooth_s``, was first back under ``band`` once the
    fault had pushed it out, before the next fault)."""
    t = series.t
    out = []
    faults = run.faults
    for j, f in enumerate(faults):
        at = float(f["t"])
        until = float(faults[j + 1]["t"]) if j + 1 < len(faults) else (
            float(t[-1]) if t.size else at)
        window = (t >= at) & (t <= until)
        detected = detection_time(run, f)
        tw = t[window]
        gap_ms = float(np.sum(np.nan_to_num(gap[window])[:-1] * np.diff(tw))) if tw.size > 1 \
            else 0.0
        rebalanced = m.recovery_time(tw, series.workload[:, window], band, smooth_s)
        out.append({
            "kind": f["kind"],
            "agent": int(f["agent"]),
            "at_s": at,
            "detected_s": detected,
            "detection_s": detected - at,
            "detection_wall_s": _wall_delay(run, f, detected),
            "coverage_gap_m_s": gap_ms,
            "rebalanced_s": rebalanced,
        })
    return out


def _wall_delay(run: RunData, fault: dict[str, Any], detected: float) -> float:
    """Wall seconds between the fault (the launcher's clock when it acted, else when
    the recorder got the news) and the tick at which it was detected (the world's clock
    when it published it, else the recorder's receipt). Both clocks are this
    machine's: simulation only."""
    if not math.isfinite(detected) or run.tick_t.size == 0:
        return math.nan
    k = min(int(np.searchsorted(run.tick_t, detected)), run.tick_t.size - 1)
    acted = int(fault.get("wall_ns") or fault["log_ns"])
    return max(0.0, float(run.tick_log_ns[k] - acted) / 1e9)


def coverage_ok(gap: np.ndarray, overlap: np.ndarray, tol_m: float = 1e-6) -> np.ndarray:
    """Ticks at which the live agents' segments cover the edge with no gap and no
    overlap."""
    return (np.nan_to_num(gap, nan=np.inf) <= tol_m) & (np.nan_to_num(overlap, nan=np.inf)
                                                       <= tol_m)
