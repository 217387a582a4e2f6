"""The measures of a ring's run on a closed edge: phase and workload errors of every
neighbour pair round the ring (robot n-1 and robot 0 included), and the revisit times
of points along the closed contour against the optimum of a patrolled cycle.

The tracks are in the edge's frame: s along the contour in each robot's own frame (the
whole turn of its arc), d across it, positive into the ice. The errors and their
steady state are the chain's (``report.measures.error_measures``) on the ring's pairs;
a visit of a point is a crossing of the contour (d = 0) within the robot's radius of it,
distances taken round the ring.

A recorded ring (``ring_tracks``) comes to the same tracks as the in-process engine's:
the contour from the world's WorldInfo, each robot's true pose projected onto it tick by
tick from the last s as its agent does (``ClosedEdge.to_edge``), in the whole turn of the
arc its agent published at that tick.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agent.edgeframe import ClosedEdge
from agent.phase import position_to_phase_array as position_phase
from agent.phase import wrap_pi_array as wrap_pi
from agent.ring import frame_shift
from report.load import RunData
from report.measures import (
    POINT_STEP_M,
    VISIT_MERGE_S,
    TeamErrors,
    crossings,
    error_measures,
    hold,
    idleness_measures,
    nanmax,
    path_length_phase,
    point_visits,
    revisit_window,
    still_fraction,
    sweep_index,
    sweep_rate,
    worst_idleness,
)


@dataclass(frozen=True)
class RingEdge:
    """The closed edge as the measures see it: its length and the true patrol depth
    per bin of ``bin_m`` from s = 0 (a whole number of bins make the ring)."""

    length: float
    bin_m: float
    patrol_depth: Sequence[float]
    robot_radius: float = 0.17

    @property
    def total_workload(self) -> float:
        return float(np.sum(np.asarray(self.patrol_depth, dtype=float)) * self.bin_m)

    def workload(self, lo: np.ndarray | float, hi: np.ndarray | float) -> np.ndarray:
        """The true workload of arcs [lo, hi] in any whole turn (eq. 3.2 round a ring)."""
        return self._integral(np.asarray(hi, dtype=float)) - self._integral(
            np.asarray(lo, dtype=float))

    def _integral(self, s: np.ndarray) -> np.ndarray:
        depth = np.asarray(self.patrol_depth, dtype=float)
        edges = self.bin_m * np.arange(depth.size + 1)
        area = np.concatenate([[0.0], np.cumsum(depth * self.bin_m)])
        turns = np.floor(s / self.length)
        return turns * area[-1] + np.interp(s - turns * self.length, edges, area)


def contour_edge(contour: Sequence[float]) -> ClosedEdge:
    """The closed edge of WorldInfo's flat contour [x0, y0, x1, y1, ...]."""
    pts = [float(v) for v in contour]
    return ClosedEdge(list(zip(pts[0::2], pts[1::2], strict=True)))


def ring_edge_of(info: dict[str, object]) -> RingEdge:
    """The ring as the measures see it, from a recorded WorldInfo (as a dict)."""
    depth = info.get("patrol_depth") or ()
    assert isinstance(depth, (list, tuple))
    return RingEdge(float(info["edge_hi"]) - float(info["edge_lo"]),  # type: ignore[arg-type]
                    float(info["bin_m"]), tuple(float(d) for d in depth),  # type: ignore[arg-type]
                    float(info.get("robot_radius", 0.17)))  # type: ignore[arg-type]


@dataclass
class RingTracks:
    """A recorded ring's run on its ticks, arrays (robots, ticks) in id order: the true
    pose (x, y; s in each agent's frame, d) and what each agent published."""

    t: np.ndarray
    ids: list[int]
    x: np.ndarray
    y: np.ndarray
    s: np.ndarray
    d: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    direction: np.ndarray
    phase: np.ndarray
    workload: np.ndarray


def ring_tracks(t: np.ndarray, edge: ClosedEdge, truth: dict[int, tuple[np.ndarray, ...]],
                states: dict[int, tuple[np.ndarray, ...]]) -> RingTracks:
    """Every robot's track and published state held on the ticks ``t``: ``truth`` by id
    (t, x, y, theta) and ``states`` by id (t, lo, hi, direction, phase, workload). The
    true s follows the pose from tick to tick as the agent's own frame does (the
    projection from the last s, the first one without), unwrapped as the agent does by
    the arc it steered with, then put in the whole turn of the arc published at that
    tick."""
    ids = sorted(states)
    n, ticks = len(ids), t.size
    arrays = [np.full((n, ticks), np.nan) for _ in range(9)]
    x, y, s, d, lo, hi, direction, phase, work = arrays
    for j, rid in enumerate(ids):
        st = states[rid]
        for row, values in zip((lo, hi, direction, phase, work), st[1:], strict=True):
            row[j] = hold(st[0], values, t)
        if rid not in truth:
            continue
        tr = truth[rid]
        x[j], y[j] = hold(tr[0], tr[1], t), hold(tr[0], tr[2], t)
        th = hold(tr[0], tr[3], t)
        hint: float | None = None
        for k in range(ticks):
            if not (np.isfinite(x[j, k]) and np.isfinite(lo[j, k])):
                continue
            if hint is None:
                hint = edge.project(float(x[j, k]), float(y[j, k]))[0]
            sk, d[j, k], _ = edge.to_edge(float(x[j, k]), float(y[j, k]), float(th[k]), hint)
            hint = sk
            # as the agent unwraps it: by the arc it steered with (the tick before's), then
            # into the turn of the arc it ends the tick with (deploy.engine's tracks)
            before = k - 1 if k > 0 and np.isfinite(lo[j, k - 1]) else k
            sk += frame_shift(sk, 0.5 * (lo[j, before] + hi[j, before]), edge.length)
            s[j, k] = sk + frame_shift(sk, 0.5 * (lo[j, k] + hi[j, k]), edge.length)
    return RingTracks(t, ids, x, y, s, d, lo, hi, direction, phase, work)


def ring_pairs(n: int) -> list[tuple[int, int]]:
    """Neighbour pairs of a ring of n: (i, i + 1 mod n); one pair for two robots."""
    if n < 2:
        return []
    return [(i, (i + 1) % n) for i in range(n if n > 2 else 1)]


def ring_errors(t: np.ndarray, s: np.ndarray, d: np.ndarray, lo: np.ndarray,
                hi: np.ndarray, direction: np.ndarray, seen_phase: np.ndarray,
                seen_workload: np.ndarray, edge: RingEdge) -> TeamErrors:
    """Errors of every pair round the ring, arrays (robots, samples): position phase
    (eq. 3.1) from the true s on each robot's arc, the path-length phase from the path
    in the edge's frame, the true workload of each arc, and what the agents published."""
    n = s.shape[0]
    pairs = ring_pairs(n)
    phase = position_phase(s, lo, hi, direction)
    path = np.vstack([path_length_phase(s[j], d[j], direction[j]) for j in range(n)])
    work = edge.workload(lo, hi)

    def errors(values: np.ndarray, wrap: bool) -> np.ndarray:
        rows = np.vstack([values[b] - values[a] for a, b in pairs])
        return wrap_pi(rows) if wrap else rows

    return TeamErrors(
        t=t, pairs=pairs, phase=errors(phase, True), phase_path=errors(path, True),
        workload=errors(work, False), workload_agents=errors(seen_workload, False),
        phase_agents=errors(seen_phase, True), ids=list(range(n)),
        live=np.ones(s.shape, dtype=bool))


def ring_visit_gaps(t: np.ndarray, s: np.ndarray, d: np.ndarray, direction: np.ndarray,
                    edge: RingEdge, t_from: float, t_to: float
                    ) -> tuple[np.ndarray, list[np.ndarray | None], np.ndarray]:
    """Points every POINT_STEP_M round the ring and, per point, the gaps between its
    visits in [t_from, t_to] and its worst idleness there: a visit is a crossing of the
    contour within the robot radius, round the ring, one per robot sweep."""
    visit_t, visit_s, group = [np.empty(0)], [np.empty(0)], [np.empty(0, np.int64)]
    for j in range(s.shape[0]):
        tc, sc = crossings(t, s[j], d[j])
        sweep = j * 1_000_000 + sweep_index(t, direction[j], tc)
        wrapped = np.mod(sc, edge.length)
        for turn in (-1.0, 0.0, 1.0):  # a visit near s = 0 is near s = L too
            visit_t.append(tc)
            visit_s.append(wrapped + turn * edge.length)
            group.append(sweep)
    count = max(1, int(math.floor(edge.length / POINT_STEP_M)))
    points = np.arange(count) * (edge.length / count)
    visits = point_visits(points, np.concatenate(visit_t), np.concatenate(visit_s),
                          edge.robot_radius, VISIT_MERGE_S, np.concatenate(group))
    gaps: list[np.ndarray | None] = []
    for times in visits:
        inside = times[(times >= t_from) & (times <= t_to)]
        gaps.append(np.diff(inside) if inside.size >= 2 else None)
    worst = np.array([worst_idleness(v, t_from, t_to, float(t[0])) for v in visits])
    return points, gaps, worst


def ring_measures(t: np.ndarray, s: np.ndarray, d: np.ndarray, lo: np.ndarray,
                  hi: np.ndarray, direction: np.ndarray, seen_phase: np.ndarray,
                  seen_workload: np.ndarray, edge: RingEdge) -> dict[str, float]:
    """Every measure of a ring's run, as ``report.measures.team_measures`` gives a
    chain's: errors and their steady state over the last quarter, revisit over the
    second half against the closed edge's optimum L / (n v) (``revisit_worst_ratio``)
    and, beside it, against a partitioned back-and-forth patrol's 2 L / (n v)
    (``revisit_worst_ratio_partition``), which is what robots that each sweep their own
    arc to and fro can reach at best."""
    errors = ring_errors(t, s, d, lo, hi, direction, seen_phase, seen_workload, edge)
    out = error_measures(errors, edge.total_workload)
    t_from, t_to = revisit_window(t)
    _, gaps, worst = ring_visit_gaps(t, s, d, direction, edge, t_from, t_to)
    n = s.shape[0]
    rate = sweep_rate([(t, s[j]) for j in range(n)], t_from, t_to,
                      [(t, direction[j]) for j in range(n)])
    out.update(idleness_measures(gaps, t_from, t_to, rate, edge.length, closed=True,
                                 worst_per_point=worst))
    out["revisit_worst_ratio_partition"] = out["revisit_worst_ratio"] / 2.0
    out["edge_length_m"] = edge.length
    still_from = float(t[0] + 0.75 * (t[-1] - t[0]))
    out["still_frac_max"] = nanmax(np.asarray(
        [still_fraction(t, s[j], d[j], still_from) for j in range(n)]))
    return out


def ring_figures(gmap: object, t: np.ndarray, x: np.ndarray, y: np.ndarray,
                 errors: TeamErrors, lo: np.ndarray, mean_workload: float,
                 out_dir: object, edge: ClosedEdge | None = None) -> list[str]:
    """``map.png`` (the floe, its closed contour, each robot's arc at the end and its
    track over the last eighth of the run) and ``errors.png`` (phase and relative
    workload error of every pair round the ring against time); the files' names.
    ``gmap`` (a GridMap) draws the ice and algae under the contour; with None, ``edge``
    (the contour of a recording) is drawn alone."""
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from simworld.maps import GridMap

    out = Path(str(out_dir))
    colours = plt.get_cmap("tab10")
    fig, ax = plt.subplots(figsize=(7, 7))
    if isinstance(gmap, GridMap):
        edge = gmap.closed_edge
        kind = gmap.ice.astype(int) + gmap.algae.astype(int)
        palette = np.array([[0.55, 0.7, 1.0], [1.0, 1.0, 1.0], [0.45, 0.85, 0.45]])
        ax.imshow(palette[kind], origin="lower",
                  extent=(0.0, gmap.width_m, gmap.y_bottom, gmap.y_top))
    assert edge is not None, "a map or a contour to draw"
    pts = np.asarray(edge.points + edge.points[:1])
    ax.plot(pts[:, 0], pts[:, 1], color="k", lw=1.0, label="closed edge (s = 0 at the dot)")
    ax.plot(*edge.points[0], "ko", ms=4)
    n = x.shape[0]
    tail = slice(int(0.875 * t.size), None)
    for i in range(n):
        ax.plot(x[i, tail], y[i, tail], color=colours(i % 10), lw=0.6, label=f"robot {i}")
        bx, by = edge.at(float(lo[i, -1]), 0.0)
        nx, ny = edge.at(float(lo[i, -1]), 1.2)
        ox, oy = edge.at(float(lo[i, -1]), -1.2)
        ax.plot([ox, nx], [oy, ny], color=colours(i % 10), lw=2.0)
        ax.plot(bx, by, "o", color=colours(i % 10), ms=5)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    name = gmap.name if isinstance(gmap, GridMap) else "closed edge"
    ax.set_title(f"{name}\n{n} robots; bars: where each arc starts at the end", fontsize=9)
    ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "map.png", dpi=110)
    plt.close(fig)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for p, (a, b) in enumerate(errors.pairs):
        a1.plot(errors.t, errors.phase[p], lw=0.6, label=f"{a}-{b}")
        if mean_workload > 0:
            a2.plot(errors.t, 100.0 * errors.workload[p] / mean_workload, lw=0.6)
    a1.set_ylabel("phase error (rad)")
    a1.legend(fontsize=7, ncol=4)
    a2.set_ylabel("workload error (% of mean)")
    a2.set_xlabel("t (s)")
    a1.set_title("every neighbour pair round the ring, the pair (n-1, 0) included")
    fig.tight_layout()
    fig.savefig(out / "errors.png", dpi=110)
    plt.close(fig)
    return ["map.png", "errors.png"]


def ring_union(lo: np.ndarray, hi: np.ndarray, length: float) -> tuple[float, float]:
    """Length of the ring covered by no arc, and the length covered more than once, of
    arcs [lo, hi] each in its own frame of s (NaN: no arc): each is put in [0, L) by
    whole turns, the part past L wrapped to the start."""
    ok = np.isfinite(lo) & np.isfinite(hi) & (hi > lo)
    lo, hi = lo[ok], hi[ok]
    start = np.mod(lo, length)
    end = start + np.minimum(hi - lo, length)
    pieces = [(a, min(b, length)) for a, b in zip(start, end, strict=True)]
    pieces += [(0.0, b - length) for b in end if b > length]
    covered, reach = 0.0, 0.0
    for a, b in sorted(pieces):
        if b > reach:
            covered += b - max(a, reach)
            reach = b
    total = float(np.sum(hi - lo))
    return length - covered, max(0.0, total - covered)


def ring_coverage(lo: np.ndarray, hi: np.ndarray, live: np.ndarray, length: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Gap and overlap (m) round the ring of the live robots' arcs at each sample; the
    arrays (robots, samples), ``live`` which robot is in the team then."""
    ticks = lo.shape[1]
    gap, overlap = np.full(ticks, np.nan), np.full(ticks, np.nan)
    for k in range(ticks):
        if live[:, k].any():
            gap[k], overlap[k] = ring_union(lo[live[:, k], k], hi[live[:, k], k], length)
    return gap, overlap


def live_ring_workload_errors(lo: np.ndarray, hi: np.ndarray, live: np.ndarray,
                              edge: RingEdge) -> np.ndarray:
    """The true workload error of every pair of live neighbours round the ring at each
    sample, (robots, samples), NaN-padded: the pairs change as robots leave and come
    back (robot ids[j] and the next live id round the ring; none with one robot, one
    pair with two)."""
    work = edge.workload(np.nan_to_num(lo), np.nan_to_num(hi))
    out = np.full(lo.shape, np.nan)
    for k in range(lo.shape[1]):
        ids = np.flatnonzero(live[:, k])
        for row, (a, b) in enumerate(ring_pairs(ids.size)):
            out[row, k] = work[ids[b], k] - work[ids[a], k]
    return out


@dataclass(frozen=True)
class RingFaults:
    """A ring's run with faults, on its time grid: the gap and overlap round the ring of
    the live robots' arcs, and one object per fault as ``report.faults.fault_measures``
    gives a chain's (when noticed, the contour unowned meanwhile, when rebalanced)."""

    gap: np.ndarray
    overlap: np.ndarray
    faults: list[dict[str, object]]


def ring_faults(run: RunData, t: np.ndarray, tracks: RingTracks, edge: RingEdge,
                band: float, smooth_s: float) -> RingFaults:
    """Fault measures of a recorded ring: a robot is live while it is in the world's live
    list with a recent state (``report.series.live_matrix``); the workload error is that
    of the live neighbours round the ring (``live_ring_workload_errors``)."""
    from report.faults import fault_measures
    from report.series import live_matrix

    live = live_matrix(run, t, tracks.ids)
    gap, overlap = ring_coverage(tracks.lo, tracks.hi, live, edge.length)
    work = live_ring_workload_errors(tracks.lo, tracks.hi, live, edge)
    unknown = np.full(work.shape, np.nan)
    series = TeamErrors(t=t, pairs=[], phase=unknown, phase_path=unknown, workload=work,
                        workload_agents=unknown, phase_agents=unknown, ids=tracks.ids,
                        live=live)
    return RingFaults(gap, overlap, fault_measures(run, series, gap, band, smooth_s))
