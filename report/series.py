"""A recorded run as one table on one time grid (the ticks), and its error series:
phase and workload errors per neighbour pair. Pure: arrays in, arrays out."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from report import measures as m
from report.load import RunData

# The error series of a recorded run: the same as an in-process run's (one
# implementation, ``measures.team_errors``).
ErrorSeries = m.TeamErrors
active_pairs = m.active_pairs
NO_EDGE = m.EdgeModel(math.nan, math.nan, 0.1, ())  # a recording with no edge at all


def edge_model(run: RunData) -> m.EdgeModel | None:
    """The edge of a recorded run as the measures see it: its ends (the world's, else
    the agents'), and from WorldInfo the true patrol depth, the local edge's shape
    (straight at y = 0 in recordings without one) and the robots' radius."""
    if run.edge is None:
        return None
    info = run.info
    return m.EdgeModel(
        edge_lo=run.edge[0],
        edge_hi=run.edge[1],
        bin_m=float(info.get("bin_m") or 0.1),
        patrol_depth=tuple(info.get("patrol_depth") or ()),
        edge_y=tuple(info.get("edge_y") or ()),
        robot_radius=float(info.get("robot_radius", 0.17)),
        frame_t=tuple(t for t, _ in run.depth_frames),
        frames=tuple(tuple(d) for _, d in run.depth_frames),
        change_windows=tuple(info.get("change_windows") or ()),
    )


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


@dataclass(frozen=True)
class RunTable:
    """A recorded run as one table, built once (``run_table``) for every measure and
    figure: the time grid (the ticks), the agents that published (``ids``, in id
    order: neighbours are consecutive), each one's published state and its robot's
    track held at every tick (arrays of shape (robots, ticks)), who was in the team
    (``live``), and the edge as the measures see it."""

    run: RunData
    t: np.ndarray
    ids: list[int]
    x: np.ndarray
    y: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    direction: np.ndarray
    phase: np.ndarray
    workload: np.ndarray
    path: np.ndarray  # the path-length phase along each track as recorded, held
    live: np.ndarray
    edge: m.EdgeModel | None
    cycle: np.ndarray  # the team's cycle each agent followed, s

    @cached_property
    def errors(self) -> ErrorSeries:
        """Errors per neighbour pair on the ticks (``measures.team_errors``)."""
        return m.team_errors(
            self.t, self.x, self.y, self.lo, self.hi, self.direction, self.phase,
            self.workload, self.edge or NO_EDGE, live=self.live, ids=self.ids,
            phase_path=self.path,
        )

    def live_segments(self) -> tuple[np.ndarray, np.ndarray]:
        """Every live agent's published segment at each tick, NaN while out of the team."""
        return np.where(self.live, self.lo, np.nan), np.where(self.live, self.hi, np.nan)


def run_table(run: RunData) -> RunTable:
    """The run's one table: each agent's state and each robot's track (truth, else
    (hardware) the agents' poses) held at every tick, for at most ``max_age_s``."""
    t = time_grid(run)
    age = max_age_s(run)
    tracks = run.positions
    ids = sorted(run.states)  # every agent that published
    unknown = np.full(t.shape, np.nan)
    rows: dict[str, list[np.ndarray]] = {
        name: [] for name in ("x", "y", "lo", "hi", "direction", "phase", "workload", "path",
                              "cycle")
    }
    for i in ids:
        st = run.states[i]
        rows["lo"].append(m.hold(st.t, st.lo, t, age))
        rows["hi"].append(m.hold(st.t, st.hi, t, age))
        rows["direction"].append(m.hold(st.t, st.direction, t, age))
        rows["phase"].append(m.hold(st.t, st.phase, t, age))
        rows["workload"].append(m.hold(st.t, st.workload, t, age))
        rows["cycle"].append(m.hold(st.t, st.cycle_s, t, age))
        tr = tracks.get(i)
        if tr is None:
            rows["x"].append(unknown)
            rows["y"].append(unknown)
            rows["path"].append(unknown)
        else:
            rows["x"].append(m.hold(tr.t, tr.x, t, age))
            rows["y"].append(m.hold(tr.t, tr.y, t, age))
            dir_on_track = m.hold(st.t, st.direction, tr.t, age)
            along_path = m.path_length_phase(tr.x, tr.y, dir_on_track)
            rows["path"].append(m.hold(tr.t, along_path, t, age))
    a = {name: np.array(r).reshape(len(ids), t.size) for name, r in rows.items()}
    return RunTable(run, t, ids, a["x"], a["y"], a["lo"], a["hi"], a["direction"], a["phase"],
                    a["workload"], a["path"], live_matrix(run, t, ids), edge_model(run),
                    a["cycle"])


def error_series(run: RunData) -> ErrorSeries:
    """Errors per neighbour pair on the ticks (``run_table(run).errors``)."""
    return run_table(run).errors
