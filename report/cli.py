"""``btrack report DIR``: measures, summary.json, figures (errors.png, boundaries.png,
map.png, revisit.png) and report.md from DIR/run.mcap. ``make_report`` is the same
for the launcher."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from report.load import LoadError, load_run
from report.localization import localization_errors, summary_stats
from report.measures import WORKLOAD_REL_BAND
from report.series import run_table
from report.summary import (
    CONVERGE_SMOOTH_S,
    PHASE_BAND_RAD,
    WORKLOAD_BAND_M2,
    compute_summary,
    goals_met,
    json_safe,
    revisit,
    write_summary,
)

ROWS = (
    ("phase_sse_rad", "phase steady-state error, position-based, eq. 3.1 (rad)"),
    ("phase_max_rad", "phase error, position-based, max over last quarter (rad)"),
    ("phase_path_sse_rad", "phase steady-state error, path length (rad)"),
    ("phase_path_max_rad", "phase error, path length, max over last quarter (rad)"),
    ("workload_sse_m2", "workload steady-state error (m^2)"),
    ("workload_max_m2", "workload error, max over last quarter (m^2)"),
    ("workload_mean_m2", "mean workload per robot, edge's true workload / n (m^2)"),
    ("workload_rel_sse", "workload steady-state error / mean workload"),
    ("workload_rel_max", "workload error, max over last quarter / mean workload"),
    ("phase_sse_agents_rad", "phase steady-state error as the agents see it (rad)"),
    ("phase_max_agents_rad", "phase error as the agents see it, max over last quarter (rad)"),
    ("workload_sse_agents_m2", "workload steady-state error as the agents see it (m^2)"),
    ("workload_max_agents_m2",
     "workload error as the agents see it, max over last quarter (m^2)"),
    ("workload_rel_sse_agents",
     "workload steady-state error as the agents see it / mean workload"),
    ("phase_q1_rad", "phase error, mean first quarter (rad)"),
    ("phase_q4_rad", "phase error, mean last quarter (rad)"),
    ("workload_q1_m2", "workload error, mean first quarter (m^2)"),
    ("workload_q4_m2", "workload error, mean last quarter (m^2)"),
    ("phase_converge_s", "phase converged after (s)"),
    ("workload_converge_s", "workload converged after, absolute band (s)"),
    ("workload_rel_converge_s", "workload converged after, relative band (s)"),
    ("converge_s", "converged after, phase and absolute workload (s)"),
    ("revisit_mean_s", "revisit time (idleness), mean (s)"),
    ("revisit_std_s", "revisit time, standard deviation (s)"),
    ("revisit_worst_s", "revisit time, worst (s)"),
    ("revisit_optimum_s", "revisit time, worst of the optimal partition, 2 L / (n v) (s)"),
    ("revisit_worst_ratio", "revisit time, worst / partition optimum"),
    ("revisit_ideal_s", "revisit time, ideal mean, L / (n v) (s)"),
    ("still_frac_max", "standing still, largest fraction of the last quarter of a robot"),
    ("speedup", "speed-up (simulated / wall time)"),
    ("loc_error_mean_m", "localisation error of the agents' poses, mean (m)"),
    ("loc_error_p95_m", "localisation error of the agents' poses, 95th percentile (m)"),
    ("ticks", "ticks recorded"),
    ("ticks_expected", "ticks in the run"),
    ("invalid_messages", "invalid messages"),
    ("rejected_messages", "messages refused as implausible (recorder, agents, world)"),
    ("coverage_gap_m_s", "edge owned by no live agent, integrated (m s)"),
)


def _fmt(value: Any) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _recording_note(summary: dict[str, Any]) -> list[str]:
    """A warning paragraph when the recording does not hold the whole run."""
    if summary.get("recording_complete", True):
        return []
    return [f"**This recording is incomplete**: {summary.get('recording_note')}. Every "
            "measure below is of the part it holds.", ""]


def _positions_note(source: Any) -> list[str]:
    """A warning paragraph when the measures could not use the simulator's truth."""
    if source == "poses":
        return ["**No ground truth in this recording** (a hardware run): positions, "
                "position-based errors, tracks and revisit times come from the poses the "
                "agents were given (the localizer's), so they are only as good as those "
                "poses.", ""]
    if source == "none":
        return ["**No positions in this recording**: only the agents' own view is "
                "measured.", ""]
    return []


def report_markdown(
    summary: dict[str, Any],
    phase_band: float,
    workload_band: float,
    extra: dict[str, Any] | None = None,
) -> str:
    head = ", ".join(
        f"{k} {_fmt(summary.get(k))}"
        for k in ("map", "start", "robots", "localization", "seed", "duration_s")
    )
    lines = [
        "# Run report",
        "",
        head,
        "",
        *_recording_note(summary),
        "| measure | value |",
        "| --- | --- |",
    ]
    lines += [f"| {label} | {_fmt(summary.get(key))} |" for key, label in ROWS]
    lines += [f"| {label} | {_fmt(value)} |" for label, value in (extra or {}).items()]
    lines += [
        "",
        f"Steady state: mean and max of |e| over neighbour pairs and the last quarter of "
        f"the run; convergence bands {phase_band} rad, {workload_band} m^2 and "
        f"{100 * WORKLOAD_REL_BAND:g} % of the mean workload (max over pairs, averaged "
        f"over the trailing {CONVERGE_SMOOTH_S:g} s); workload error from the true patrol "
        "depth. Revisit times over the second half: for points every 0.1 m along the "
        "edge, the times between visits (crossings of the local edge within a robot's "
        "radius, one per robot sweep), against the optimum of a partitioned patrol, "
        "whose worst is 2 L / (n v) with n v the team's measured along-edge sweep rate. "
        "Standing still: moving less than 1 mm per 0.1 s tick. 'As the agents see it': "
        "from the phases and workloads the agents published, each from its own pose "
        "estimate (how the thesis measured its robot runs, table 7.3).",
        "",
        *goals_markdown(summary),
        *_positions_note(summary.get("positions_from")),
        "![errors](errors.png)",
        "",
        "![boundaries](boundaries.png)",
        "",
        "![map](map.png)",
        "",
        "![revisit](revisit.png)",
        "",
        "![localization](localization.png)",
        "",
        "Figures: [errors.png](errors.png), [boundaries.png](boundaries.png), "
        "[map.png](map.png), [revisit.png](revisit.png), "
        "[localization.png](localization.png); numbers: "
        "[summary.json](summary.json).",
        "",
    ]
    return "\n".join(lines)


def goals_markdown(summary: dict[str, Any]) -> list[str]:
    """The goals table (``summary.GOALS``): each measure against its bound, met or not,
    and a line naming those not met."""
    lines = ["## Goals", "", "| goal | value | met |", "| --- | --- | --- |"]
    missed = []
    for key, label, value, bound, met in goals_met(summary):
        verdict = "met" if met else "not met" if met is not None else "not measured"
        if not met:
            missed.append(f"{label} ({verdict})")
        lines.append(f"| {label} < {bound:g} (`{key}`) | {_fmt(value)} | {verdict} |")
    lines += ["", ("Not met: " + "; ".join(missed) + ".") if missed else "All goals met.", ""]
    return lines


def faults_markdown(faults: list[dict[str, Any]]) -> str:
    """The table of injected faults, or nothing for a run without any."""
    if not faults:
        return ""
    lines = [
        "",
        "## Faults",
        "",
        "| fault | at (s) | detected (s) | took (s sim / s wall) | edge unowned (m s) | "
        "workload rebalanced after (s) |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for f in faults:
        lines.append(
            f"| {f['kind']} agent {f['agent']} | {_fmt(f['at_s'])} | {_fmt(f['detected_s'])} "
            f"| {_fmt(f['detection_s'])} / {_fmt(f['detection_wall_s'])} | "
            f"{_fmt(f['coverage_gap_m_s'])} | {_fmt(f['rebalanced_s'])} |"
        )
    lines += [
        "",
        "Detected: when the other agents' published neighbours first reflect the fault. "
        "Edge unowned: length of edge in no live agent's segment, integrated from the "
        "fault to the next one. Rebalanced: until the worst workload error over neighbour "
        "pairs (10 s average) is back within its band for good (up to the next fault).",
        "",
    ]
    return "\n".join(lines)


def changes_markdown(spec: str, changes: list[dict[str, Any]]) -> str:
    """The table of the map's changes and the team's rebalancing after each, or nothing
    for a static map."""
    if not changes:
        return ""
    lines = [
        "",
        "## The map changed",
        "",
        f"`--change {spec}`" if spec else "",
        "",
        "| change (s) | cycle then (s) | band (m^2) | back in band after (s / cycles) | "
        "stays in band after (s / cycles) | peak error / mean workload | mean error / mean "
        "workload during |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for c in changes:
        lines.append(
            f"| {_fmt(c['t0'])} to {_fmt(c['t1'])} | {_fmt(c['cycle_s'])} | "
            f"{_fmt(c['band_m2'])} | {_fmt(c['back_s'])} / {_fmt(c['back_cycles'])} | "
            f"{_fmt(c['settled_s'])} / {_fmt(c['settled_cycles'])} | {_fmt(c['peak_rel'])} | "
            f"{_fmt(c['during_rel'])} |")
    lines += [
        "",
        f"From each change's end: the worst workload error over neighbour pairs (true "
        f"depth in force at each tick, {CONVERGE_SMOOTH_S:g} s average) against a band of "
        f"{100 * WORKLOAD_REL_BAND:g} % of the mean workload per robot then; cycles of the "
        "team's cycle at the change's end. Shaded on errors.png.",
        "",
    ]
    return "\n".join(lines)


def make_report(
    run_dir: str | Path,
    phase_band: float = PHASE_BAND_RAD,
    workload_band: float = WORKLOAD_BAND_M2,
) -> dict[str, Any]:
    """Write summary.json, errors.png, map.png and report.md into ``run_dir``; return the
    summary. Raises ``LoadError`` if run_dir/run.mcap is missing or unreadable."""
    from report.figures import (  # matplotlib only when drawing
        boundaries_figure,
        errors_figure,
        localization_figure,
        map_figure,
        revisit_figure,
    )

    run_dir = Path(run_dir)
    run = load_run(run_dir / "run.mcap")
    if run.info.get("closed"):
        return ring_report(run_dir, run)
    table = run_table(run)  # the run as one table, for every measure and figure
    rev = revisit(run, table.t)
    loc = localization_errors(run)
    summary = compute_summary(table, phase_band, workload_band, rev, loc)
    write_summary(run_dir / "summary.json", summary)
    errors_figure(table.errors, run_dir / "errors.png", run, summary.get("changes"))
    map_figure(run, run_dir / "map.png")
    boundaries_figure(table, run_dir / "boundaries.png")
    revisit_figure(rev, run_dir / "revisit.png")
    localization_figure(loc, run_dir / "localization.png", summary.get("localization"))
    extra: dict[str, Any] = {}
    for rid in sorted(loc.t):
        for which, label in (("pf", "poses given"), ("odometry", "odometry alone")):
            errors = getattr(loc, which).get(rid)
            if errors is not None:
                mean, p95 = summary_stats(errors)
                extra[f"robot {rid} localisation error, {label}, mean / p95 (m)"] = (
                    f"{_fmt(json_safe(mean))} / {_fmt(json_safe(p95))}")
    markdown = report_markdown(summary, phase_band, workload_band, extra)
    markdown += faults_markdown(summary.get("faults") or [])
    markdown += changes_markdown(summary.get("change") or "", summary.get("changes") or [])
    (run_dir / "report.md").write_text(markdown)
    return summary


# What a ring's report.md lists, as the in-process engine's does (deploy.inprocess)
RING_ROWS = (
    ("phase_sse_rad", "phase steady-state error, position-based, eq. 3.1 (rad)"),
    ("phase_max_rad", "phase error, position-based, max over last quarter (rad)"),
    ("phase_path_sse_rad", "phase steady-state error, path length (rad)"),
    ("workload_sse_m2", "workload steady-state error (m^2)"),
    ("workload_mean_m2", "mean workload per robot, the ring's true workload / n (m^2)"),
    ("workload_rel_sse", "workload steady-state error / mean workload"),
    ("workload_rel_max", "workload error, max over last quarter / mean workload"),
    ("revisit_worst_s", "revisit time, worst, second half (s)"),
    ("revisit_optimum_s", "revisit time, optimum of a patrolled cycle, L / (n v) (s)"),
    ("revisit_worst_ratio", "revisit time, worst / L / (n v)"),
    ("revisit_worst_ratio_partition", "revisit time, worst / 2 L / (n v)"),
    ("converge_s", "converged after, phase and absolute workload (s)"),
    ("edge_length_m", "the closed edge's length (m)"),
    ("still_frac_max", "standing still, largest fraction of the last quarter of a robot"),
    ("speedup", "speed-up (simulated / wall time)"),
    ("ticks", "ticks recorded"),
    ("ticks_expected", "ticks in the run"),
    ("invalid_messages", "invalid messages"),
    ("rejected_messages", "messages refused as implausible (recorder, agents, world)"),
)


def ring_report(run_dir: Path, run: Any) -> dict[str, Any]:
    """``make_report`` of a ring round a closed edge: the ring's measures
    (``report.ring.ring_measures``, every pair round the ring) from the recording, as the
    in-process engine gives them from its tracks, ``summary.json``, ``map.png``,
    ``errors.png`` and ``report.md``."""
    import numpy as np

    from report import measures as m
    from report.ring import (
        contour_edge,
        ring_edge_of,
        ring_errors,
        ring_faults,
        ring_figures,
        ring_measures,
        ring_tracks,
    )
    from report.series import time_grid
    from report.summary import recording_completeness, rejected_messages

    info = run.info
    edge = contour_edge(info["contour"])
    ring = ring_edge_of(info)
    t = time_grid(run)
    tracks = ring_tracks(
        t, edge, {r: (p.t, p.x, p.y, p.theta) for r, p in run.positions.items()},
        {r: (st.t, st.lo, st.hi, st.direction, st.phase, st.workload)
         for r, st in run.states.items()})
    tr = tracks
    result = ring_measures(t, tr.s, tr.d, tr.lo, tr.hi, tr.direction, tr.phase, tr.workload,
                           ring)
    faults = ring_faults(run, t, tr, ring, m.WORKLOAD_BAND_M2, m.CONVERGE_SMOOTH_S)
    summary: dict[str, Any] = {
        **{k: info.get(k) for k in ("map", "start", "robots", "localization", "seed",
                                    "duration_s", "odom_noise", "odom_turn_noise")},
        "closed": True,
        "speedup": m.speedup(run.tick_t, run.tick_log_ns),
        **result,
        "ticks": int(run.tick_t.size),
        **recording_completeness(run),
        "invalid_messages": int(run.invalid),
        "rejected_messages": rejected_messages(run),
        "refused": run.refused,
        "positions_from": run.positions_from,
        # the contour owned by no live robot, integrated over the run (m s), and each
        # fault's measures as a chain's (report.faults), round the ring
        "coverage_gap_m_s": float(np.sum(np.nan_to_num(faults.gap[:-1]) * np.diff(t)))
        if t.size > 1 else 0.0,
        "faults": faults.faults,
        # every robot's arc [lo, hi] in its own frame at the run's last tick
        "arcs_end": [[float(tr.lo[j, -1]), float(tr.hi[j, -1])] for j in range(len(tr.ids))],
    }
    summary = json_safe(summary)
    write_summary(run_dir / "summary.json", summary)
    errors = ring_errors(t, tr.s, tr.d, tr.lo, tr.hi, tr.direction, tr.phase, tr.workload,
                         ring)
    gmap = _ring_map(info, edge.length)
    mean = float(result["workload_mean_m2"])
    ring_figures(gmap, t, tr.x, tr.y, errors, tr.lo,
                 mean if np.isfinite(mean) else 0.0, run_dir, edge=edge)
    head = ", ".join(f"{k} {_fmt(summary.get(k))}"
                     for k in ("map", "start", "robots", "localization", "seed", "duration_s"))
    lines = ["# Run report: a ring round a closed edge", "", head, "",
             *_recording_note(summary), "| measure | value |", "| --- | --- |"]
    lines += [f"| {label} | {_fmt(summary.get(key))} |" for key, label in RING_ROWS]
    lines += ["", "Every pair of neighbours round the ring, the pair (n-1, 0) included; s "
              "along the contour, revisit times of points every 0.1 m round it against "
              "L / (n v), the optimum of a patrolled cycle (each robot sweeping its own arc "
              "to and fro reaches 2 L / (n v) at best).", "", *goals_markdown(summary),
              *faults_markdown(summary["faults"]).splitlines(),
              "![map](map.png)", "", "![errors](errors.png)", ""]
    (run_dir / "report.md").write_text("\n".join(lines))
    return summary


def _ring_map(info: dict[str, Any], length: float) -> Any:
    """The recorded map rebuilt from its name, to draw under the contour; None where it
    cannot be (a PNG not here, or one whose contour is not the recording's)."""
    from simworld.maps import MapError, load_map

    try:
        gmap = load_map(str(info.get("map")), seed=int(info.get("seed") or 1))
        if not gmap.closed or abs(gmap.closed_edge.length - length) > 1e-6 * length:
            return None
    except (MapError, OSError, ValueError):
        return None
    return gmap


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="btrack report",
        description="Measures, summary.json, figures (errors, boundaries, map, revisit) and "
        "report.md from DIR/run.mcap.",
    )
    parser.add_argument("dir", metavar="DIR", help="run directory holding run.mcap")
    parser.add_argument("--phase-band", type=float, default=PHASE_BAND_RAD, metavar="RAD")
    parser.add_argument("--workload-band", type=float, default=WORKLOAD_BAND_M2, metavar="M2")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    try:
        summary = make_report(args.dir, args.phase_band, args.workload_band)
    except LoadError as exc:
        print(f"btrack report: {exc}", file=sys.stderr)
        return 2
    print(
        f"btrack report: wrote {Path(args.dir) / 'report.md'} "
        f"(phase sse {_fmt(summary['phase_sse_rad'])} rad, "
        f"workload sse {_fmt(summary['workload_sse_m2'])} m^2)"
    )
    if not summary.get("recording_complete", True):
        print(f"btrack report: the recording is incomplete: {summary['recording_note']}",
              file=sys.stderr)
    return 0
