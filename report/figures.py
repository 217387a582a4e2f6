"""Figures of a recorded run: errors.png (errors per pair against time, as thesis
fig. 7.1), boundaries.png (each robot's segment against time), map.png (top-down view
of water, ice, algae and the robots' tracks, as figs. 6.10 and 7.2) and revisit.png
(time between visits along the edge)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from report.load import RunData  # noqa: E402
from report.localization import LocErrors  # noqa: E402
from report.series import NO_EDGE, ErrorSeries, RunTable, edge_model  # noqa: E402
from report.summary import Revisit  # noqa: E402

WATER = "#3a7dc9"
ICE = "#ffffff"
ALGAE = "#3fa34d"
MAX_POINTS = 20000  # per line; longer tracks are thinned for drawing only


def _thin(n: int) -> slice:
    return slice(None, None, max(1, n // MAX_POINTS))


def errors_figure(series: ErrorSeries, path: str | Path, run: RunData | None = None,
                  changes: list[dict[str, Any]] | None = None) -> None:
    """Phase error and workload error per neighbour pair against time, two panels; the
    map's ``changes`` (``measures.change_recovery``'s rows) shaded, each with the time
    the workload error was back in its band after it."""
    fig, (ax_phase, ax_work) = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    t = series.t
    step = _thin(t.size)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for j, (a, b) in enumerate(series.pairs):
        c = colours[j % len(colours)]
        label = f"pair {a}-{b}"
        ax_phase.plot(
            t[step], series.phase[j][step], color=c, lw=1.2, label=f"{label} (position, eq. 3.1)"
        )
        ax_phase.plot(
            t[step],
            series.phase_path[j][step],
            color=c,
            lw=0.8,
            ls=":",
            label=f"{label} (path length)",
        )
        ax_work.plot(
            t[step], series.workload[j][step], color=c, lw=1.2, label=f"{label} (true depth)"
        )
        ax_work.plot(
            t[step],
            series.workload_agents[j][step],
            color=c,
            lw=0.8,
            ls="--",
            label=f"{label} (agents' estimate)",
        )
    ax_phase.set_title("Phase error e_phi,i = wrap(phi_i+1 - phi_i)")
    ax_phase.set_ylabel("phase error (rad)")
    ax_phase.set_ylim(-np.pi * 1.05, np.pi * 1.05)
    if changes and len(series.pairs) and t.size:  # the changes' scale, not the start's
        since = np.abs(series.workload[:, t >= float(changes[0]["t0"])])
        top = float(np.nanmax(since)) if since.size and np.isfinite(since).any() else 0.0
        if top > 0:
            ax_work.set_ylim(-1.2 * top, 1.2 * top)
            ax_work.set_title("Workload error e_Psi,i = Psi_i+1 - Psi_i (scaled to the "
                              "errors from the first change on)")
    if not changes:
        ax_work.set_title("Workload error e_Psi,i = Psi_i+1 - Psi_i")
    ax_work.set_ylabel("workload error (m^2)")
    ax_work.set_xlabel("simulation time (s)")
    for ax in (ax_phase, ax_work):
        if run is not None:
            _mark_faults(ax, run)
        _mark_changes(ax, changes or [], ax is ax_work, float(t[-1]) if t.size else 0.0)
        ax.axhline(0.0, color="grey", lw=0.6)
        ax.grid(True, alpha=0.3)
        if series.pairs:
            ax.legend(loc="upper right", fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def edge_outline(run: RunData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the map draws of the edge, from WorldInfo: the bins' sides (x, m), the local
    edge's y per bin (0 for recordings without the edge's shape) and the true patrol
    depth per bin, drawn above the local edge; no bins without a depth profile."""
    edge = edge_model(run)
    if edge is None or not len(edge.patrol_depth):
        return np.empty(0), np.empty(0), np.empty(0)
    depth = np.asarray(edge.patrol_depth, dtype=float)
    # WorldInfo's check keeps edge_y one per depth bin
    edge_y = np.asarray(edge.edge_y, dtype=float) if len(edge.edge_y) else np.zeros(depth.size)
    sides = np.minimum(edge.edge_lo + edge.bin_m * np.arange(depth.size + 1), edge.edge_hi)
    return sides, edge_y, depth


def map_figure(run: RunData, path: str | Path) -> None:
    """Top-down map: water below the local edge, ice above it, the algae band and the
    true patrol depth above the local edge, robot tracks."""
    info = run.info
    fig, ax = plt.subplots(figsize=(10, 6))
    edge_lo, edge_hi = run.edge or (0.0, 1.0)
    edge = edge_model(run) or NO_EDGE
    sides, edge_y, depth = edge_outline(run)
    depth_top = edge_y + depth
    min_depth = float(info.get("min_depth", 0.0))
    tracks = run.positions
    xs = [tr.x for tr in tracks.values()]
    ys = [tr.y for tr in tracks.values()]
    all_x = np.concatenate(xs + [np.array([edge_lo, edge_hi])])
    all_y = np.concatenate(ys + [np.array([-1.0, 1.0]), edge_y, depth_top])
    x0, x1 = float(all_x.min()) - 0.5, float(all_x.max()) + 0.5
    y0, y1 = float(all_y.min()) - 0.5, float(all_y.max()) + 0.5
    # water below the local edge, ice above it (the edge held flat past its ends)
    fine_x = np.linspace(x0, x1, 20 * max(edge_y.size, 10) + 1)
    fine_edge = edge.local_edge(fine_x) if np.isfinite(edge.edge_lo) else np.zeros_like(fine_x)
    ax.fill_between(fine_x, y0, fine_edge, color=WATER, alpha=0.35, lw=0)
    ax.fill_between(fine_x, fine_edge, y1, facecolor=ICE, edgecolor="none")
    if edge_y.size:
        algae = np.where(depth > min_depth, depth, 0.0)
        ax.bar(sides[:-1], algae, width=np.diff(sides), align="edge", bottom=edge_y,
               color=ALGAE, alpha=0.6, lw=0)
        ax.stairs(depth_top, sides, baseline=None, color="darkgreen", lw=1.2,
                  label="patrol depth above the local edge")
        centres = 0.5 * (sides[:-1] + sides[1:])
        ax.plot(np.concatenate([[sides[0]], centres, [sides[-1]]]),
                np.concatenate([[edge_y[0]], edge_y, [edge_y[-1]]]),
                color="black", lw=1.5, label="edge")
    else:
        ax.plot([edge_lo, edge_hi], [0.0, 0.0], color="black", lw=1.5, label="edge")
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for j, (robot, tr) in enumerate(sorted(tracks.items())):
        c = colours[j % len(colours)]
        step = _thin(tr.x.size)
        ax.plot(tr.x[step], tr.y[step], color=c, lw=0.7, label=f"robot {robot}")
        if tr.x.size:
            ax.plot(tr.x[0], tr.y[0], marker="o", ms=8, mfc=c, mec="black", ls="none")
    ax.plot([], [], marker="o", ms=8, mfc="none", mec="black", ls="none", label="start")
    ax.add_artist(ax.legend(loc="upper right", fontsize=8))
    ax.legend(
        handles=[
            Patch(color=WATER, alpha=0.35, label="water"),
            Patch(facecolor=ICE, edgecolor="grey", label="ice"),
            Patch(color=ALGAE, alpha=0.6, label="algae"),
        ],
        loc="upper left",
        fontsize=8,
    )
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x along the edge (m)")
    ax.set_ylabel("y into the ice (m)")
    source = "truth" if run.positions_from == "truth" else "agents' poses, no ground truth"
    title = f"map {info.get('map', '?')}, start {info.get('start', '?')}: robot tracks ({source})"
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _mark_changes(ax: plt.Axes, changes: list[dict[str, Any]], band: bool, t_end: float
                  ) -> None:
    """Each change of the map shaded over its window; on the workload panel (``band``)
    the band after it and a dashed line where the error was back in it."""
    for c in changes:
        t0, t1 = float(c["t0"]), float(c["t1"])
        ax.axvspan(t0, t1, color="tab:green", alpha=0.12, lw=0)
        ax.annotate("map changes", (0.5 * (t0 + t1), 1.0), xycoords=("data", "axes fraction"),
                    va="top", ha="center", fontsize=7, color="darkgreen")
        back = c.get("back_s")
        if band and isinstance(back, (int, float)) and math.isfinite(back):
            ax.axvline(t1 + back, color="darkgreen", lw=0.9, ls="--")
            cycles = c.get("back_cycles")
            text = (f"back in band {back:.0f} s" + (f" ({cycles:.1f} cycles)" if isinstance(
                cycles, (int, float)) and math.isfinite(cycles) else ""))
            ax.annotate(text, (t1 + back, 0.02), xycoords=("data", "axes fraction"),
                        rotation=90, va="bottom", ha="left", fontsize=7, color="darkgreen")
        width = c.get("band_m2")
        if band and isinstance(width, (int, float)) and math.isfinite(width):
            ax.fill_between([t1, max(t1, t_end)], -width, width, color="darkgreen",
                            alpha=0.08, lw=0)


def _mark_faults(ax: plt.Axes, run: RunData) -> None:
    """A dotted vertical line at each injected fault, labelled."""
    for f in run.faults:
        ax.axvline(float(f["t"]), color="red", lw=0.8, ls=":")
        ax.annotate(f"{f['kind']} {f['agent']}", (float(f["t"]), 1.0),
                    xycoords=("data", "axes fraction"), rotation=90, va="top", ha="right",
                    fontsize=7, color="red")


def boundaries_figure(table: RunTable, path: str | Path) -> None:
    """Each live robot's segment [s_i, s_i+1] against time, as it published it."""
    run, t, ids = table.run, table.t, table.ids
    info = run.info
    fig, ax = plt.subplots(figsize=(10, 4.5))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    step = _thin(t.size)
    live_lo, live_hi = table.live_segments()
    for j, robot in enumerate(ids):
        c = colours[j % len(colours)]
        lo, hi = live_lo[j][step], live_hi[j][step]
        ax.fill_between(t[step], lo, hi, color=c, alpha=0.25, lw=0,
                        label=f"robot {robot}'s segment")
        ax.plot(t[step], lo, color=c, lw=0.9)
        ax.plot(t[step], hi, color=c, lw=0.9)
    if "edge_lo" in info:
        for end in (info["edge_lo"], info["edge_hi"]):
            ax.axhline(float(end), color="black", lw=0.8, ls="--")
    _mark_faults(ax, run)
    ax.set_title(f"Segments of the live robots against time (map {info.get('map', '?')}, "
                 f"start {info.get('start', '?')})")
    ax.set_xlabel("simulation time (s)")
    ax.set_ylabel("position along the edge (m)")
    ax.grid(True, alpha=0.3)
    if ids:
        ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def revisit_figure(rev: Revisit | None, path: str | Path) -> None:
    """Mean and worst time between visits of points every 0.1 m along the edge, over
    the second half of the run, against the ideal mean and the partition optimum of the
    worst for the same team speed."""
    fig, ax = plt.subplots(figsize=(10, 4))
    if rev is not None:
        mean, worst = rev.profile()
        ax.plot(rev.points, worst, color="tab:red", lw=1.0, marker=".", label="worst")
        ax.plot(rev.points, mean, color="tab:blue", lw=1.2, marker=".", label="mean")
        if np.isfinite(rev.ideal_s):
            ax.axhline(rev.ideal_s, color="black", ls="--", lw=1.0,
                       label=f"ideal mean for this team speed, L / (n v) ({rev.ideal_s:.0f} s)")
            ax.axhline(rev.optimum_s, color="tab:red", ls="--", lw=1.0,
                       label=f"partition optimum of the worst, 2 L / (n v) "
                             f"({rev.optimum_s:.0f} s)")
        ax.set_ylim(0, 1.25 * float(np.nanmax([*worst, rev.optimum_s, 1.0])))
        ax.set_title(f"Revisit time along the edge, {rev.t_from:.0f} s to {rev.t_to:.0f} s "
                     "(one visit per robot sweep)")
        ax.legend(loc="upper right", fontsize=8, ncol=2)
    else:
        ax.set_title("Revisit time along the edge: no tracks recorded")
    ax.set_xlabel("position along the edge (m)")
    ax.set_ylabel("time between visits (s)")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def localization_figure(loc: LocErrors, path: str | Path, source: str | None = None) -> None:
    """Position error against truth per robot over time: the poses the agents were
    given (solid) and odometry alone for the same run (dashed)."""
    fig, ax = plt.subplots(figsize=(10, 4.5))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for j, rid in enumerate(sorted(loc.t)):
        c = colours[j % len(colours)]
        t = loc.t[rid]
        step = _thin(t.size)
        if rid in loc.pf:
            ax.plot(t[step], loc.pf[rid][step], color=c, lw=1.0,
                    label=f"robot {rid}, {source or 'given'} poses")
        if rid in loc.odometry:
            ax.plot(t[step], loc.odometry[rid][step], color=c, lw=0.9, ls="--",
                    label=f"robot {rid}, odometry alone")
    ax.set_yscale("log")
    ax.set_ylim(1e-4, 10.0)
    ax.set_title("Localisation error against truth")
    ax.set_xlabel("simulation time (s)")
    ax.set_ylabel("position error (m)")
    ax.grid(True, which="both", alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
