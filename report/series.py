"""Error time series of a recorded run: phase and workload errors per neighbour pair
on one time grid (the ticks). Pure: arrays in, arrays out."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from report import measures as m
from report.load import RunData


@dataclass
class ErrorSeries:
    t: np.ndarray  # simulation time of each sample (the ticks), s
    pairs: list[tuple[int, int]]  # neighbour pairs (live ids next to each other), a row each
    phase: np.ndarray  # e_phi with the position-based phase (eq. 3.1), rad
    phase_path: np.ndarray  # e_phi with the path-length phase, rad
    workload: np.ndarray  # e_Psi with the true workload (true patrol depth), m^2
    workload_agents: np.ndarray  # e_Psi from the workloads the agents published, m^2
    # e_phi from the phases the agents published (each from its own pose estimate), rad:
    # the errors as the robots see them, how the thesis measured its robot runs
    phase_agents: np.ndarray


def time_grid(run: RunData) -> np.ndarray:
    """The ticks' times, or every recorded time if no tick was recorded."""
    if run.tick_t.size:
        return np.unique(run.tick_t)
    parts = [tr.t for tr in run.positions.values()] + [st.t for st in run.states.values()]
    return np.unique(np.concatenate(parts)) if parts else np.empty(0)


def max_age_s(run: RunData) -> float:
    """How long a robot's last message stands for it (a dead agent drops out after this)."""
    dt = float(run.info.get("dt") or 0.1)
    return max(10.0 * dt, 1.0)


def live_matrix(run: RunData, t: np.ndarray, ids: list[int]) -> np.ndarray:
    """live[j, k]: robot ids[j] is in the team at t[k]: in the world's live list of that
    tick (Zenoh liveliness) and with a recent state. Without ticks, a recent state."""
    age = max_age_s(run)
    live = np.zeros((len(ids), t.size), dtype=bool)
    for j, rid in enumerate(ids):
        st = run.states.get(rid)
        if st is not None:
            live[j] = np.isfinite(m.hold(st.t, st.lo, t, age))
    if run.tick_live and len(run.tick_live) == run.tick_t.size and t.size:
        idx = np.clip(np.searchsorted(run.tick_t, t, side="right") - 1, 0, run.tick_t.size - 1)
        for j, rid in enumerate(ids):
            in_tick = np.fromiter((rid in run.tick_live[i] for i in idx), bool, idx.size)
            live[j] &= in_tick
    return live


def active_pairs(ids: list[int], live: np.ndarray) -> tuple[list[tuple[int, int]], np.ndarray]:
    """Neighbour pairs over time: (a, b) is a pair while both are live and no live id
    lies between them (a robot that left makes its two neighbours a pair). Returns the
    pairs that ever occur and active[p, k]."""
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


def error_series(run: RunData) -> ErrorSeries:
    t = time_grid(run)
    age = max_age_s(run)
    # every agent that published; positions from truth, else (hardware) the agents' poses
    tracks = run.positions
    ids = sorted(run.states)
    pairs, active = active_pairs(ids, live_matrix(run, t, ids))
    depth = run.info.get("patrol_depth") or []
    edge_lo = float(run.info.get("edge_lo", 0.0))
    bin_m = float(run.info.get("bin_m") or 0.1)

    phase: dict[int, np.ndarray] = {}
    phase_path: dict[int, np.ndarray] = {}
    work: dict[int, np.ndarray] = {}
    work_agents: dict[int, np.ndarray] = {}
    phase_agents: dict[int, np.ndarray] = {}
    unknown = np.full(t.shape, np.nan)
    for i in ids:
        st = run.states[i]
        lo = m.hold(st.t, st.lo, t, age)
        hi = m.hold(st.t, st.hi, t, age)
        tr = tracks.get(i)
        if tr is None:
            phase[i] = phase_path[i] = unknown
        else:
            x = m.hold(tr.t, tr.x, t, age)
            direction = m.hold(st.t, st.direction, t, age)
            phase[i] = m.position_phase(x, lo, hi, direction)
            dir_on_track = m.hold(st.t, st.direction, tr.t, age)
            along_path = m.path_length_phase(tr.x, tr.y, dir_on_track)
            phase_path[i] = m.hold(tr.t, along_path, t, age)
        work[i] = (
            m.true_workload(lo, hi, edge_lo, bin_m, depth)
            if len(depth)
            else unknown
        )
        work_agents[i] = m.hold(st.t, st.workload, t, age)
        phase_agents[i] = m.hold(st.t, st.phase, t, age)

    def errors(values: dict[int, np.ndarray], wrap: bool) -> np.ndarray:
        if not pairs:
            return np.empty((0, t.size))
        return np.where(active, m.pair_errors(values, pairs, wrap), np.nan)

    return ErrorSeries(
        t=t,
        pairs=pairs,
        phase=errors(phase, True),
        phase_path=errors(phase_path, True),
        workload=errors(work, False),
        workload_agents=errors(work_agents, False),
        phase_agents=errors(phase_agents, True),
    )
