"""The report of a suite of runs: ``summary.json`` (``{"cases": [...]}``), the thesis's
tables with our value beside the thesis's in every cell (``report.md``) and a figure
of both (``suite.png``)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from report.summary import json_safe
from report.thesis import (
    AGENT_KEYS,
    PHASE_SSE_RAD,
    TRUE_KEYS,
    WORKLOAD_SSE_M2,
    below_thesis,
    thesis_table,
)


def write_suite_report(out: Path, cases: list[dict[str, Any]], settings: dict[str, Any]) -> int:
    """Write out/summary.json, out/report.md and out/suite.png; return how many cases
    are below the thesis in both tables."""
    below = _count_below(cases)
    below_agents = _count_below(cases, AGENT_KEYS)
    doc = {**settings, "below_thesis": below, "below_thesis_agents": below_agents,
           "cases": cases}
    (out / "summary.json").write_text(json.dumps(json_safe(doc), indent=2, allow_nan=False)
                                      + "\n")
    suite_figure(cases, out / "suite.png")
    (out / "report.md").write_text(suite_markdown(cases, settings, below, below_agents))
    return below


def _count_below(cases: list[dict[str, Any]], keys: tuple[str, str] = TRUE_KEYS) -> int:
    return sum(1 for p, w in (below_thesis(c, keys) for c in cases) if p and w)


def _ratio_range(cases: list[dict[str, Any]], key: str, thesis_key: str) -> str:
    ratios = [c[thesis_key] / c[key] for c in cases
              if isinstance(c.get(key), (int, float)) and c[key] > 0
              and math.isfinite(c.get(thesis_key, math.nan))]
    if not ratios:
        return "n/a"
    top = max(ratios)
    return f"{min(ratios):.1f}x to " + (">1000x" if top > 1000 else f"{top:.1f}x")


def suite_markdown(cases: list[dict[str, Any]], settings: dict[str, Any], below: int,
                   below_agents: int | None = None) -> str:
    lines = [
        "# Thesis suite: tables 7.1 and 7.2, ours beside the thesis's",
        "",
        ", ".join(f"{k} {v}" for k, v in settings.items()),
        "",
        f"**{below} of {len(cases)} cases below the thesis in both tables**, measured "
        "against ground truth. Each cell: "
        "our steady-state error / the thesis's (how many times ours is smaller). "
        "Steady state is the mean |e| over neighbour pairs and the last quarter of the "
        "run; the workload error uses the map's true patrol depth.",
        "",
    ]
    lines += thesis_table(cases, "phase_sse_rad", PHASE_SSE_RAD,
                          "Table 7.1: phase steady-state error (rad), position-based phase")
    lines.append("")
    lines += thesis_table(cases, "workload_sse_m2", WORKLOAD_SSE_M2,
                          "Table 7.2: workload steady-state error (m^2)")
    lines += [
        "",
        f"Phase: ours {_ratio_range(cases, 'phase_sse_rad', 'thesis_phase_sse_rad')} "
        "below the thesis; workload: ours "
        f"{_ratio_range(cases, 'workload_sse_m2', 'thesis_workload_sse_m2')} below.",
        "",
        "![ours against the thesis](suite.png)",
        "",
    ]
    if below_agents is not None:
        lines += [
            "## As the robots see it",
            "",
            f"{below_agents} of {len(cases)} cases below the thesis in both tables when the "
            "errors are taken from the phases and workloads the agents published, each "
            "from its own pose estimate: how the thesis measured its robot runs (table "
            "7.3), which had no ground truth. With truth poses the two views agree; with "
            "odometry alone they part by the robots' drift.",
            "",
        ]
        lines += thesis_table(cases, AGENT_KEYS[0], PHASE_SSE_RAD,
                              "Phase steady-state error as the agents see it (rad)")
        lines.append("")
        lines += thesis_table(cases, AGENT_KEYS[1], WORKLOAD_SSE_M2,
                              "Workload steady-state error as the agents see it (m^2)")
        lines.append("")
    lines += [
        "## Other measures (against truth)",
        "",
        "| case | phase, path length (rad) | phase, path length, max (rad) | "
        "phase max (rad) | workload max (m^2) | workload / mean workload, "
        "steady state / max (%) | converged after (s) | revisit mean / worst / ideal (s) | "
        "speed-up | wall (s) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]

    def f(value: Any, digits: int = 3) -> str:
        return f"{value:.{digits}f}" if isinstance(value, (int, float)) else "n/a"

    def times(value: Any) -> str:
        return f"{value:.0f}x" if isinstance(value, (int, float)) else "n/a"

    def percent(value: Any) -> str:
        return f"{100 * value:.2f}" if isinstance(value, (int, float)) else "n/a"

    for c in cases:
        name = f"{c.get('map')} {c.get('start')}"
        if c.get("dir"):  # a bus run's own directory, with its report
            name = f"[{name}]({c['dir']}/report.md)"
        if "error" in c:
            lines.append(f"| {name} | {c['error']} | | | | | | | | |")
            continue
        # phase_sse_path_rad: the key of summaries written before phase_path_sse_rad
        path_sse = c.get("phase_path_sse_rad", c.get("phase_sse_path_rad"))
        lines.append(
            f"| {name} | {f(path_sse)} | {f(c.get('phase_path_max_rad'))} | "
            f"{f(c.get('phase_max_rad'))} | {f(c.get('workload_max_m2'))} | "
            f"{percent(c.get('workload_rel_sse'))} / {percent(c.get('workload_rel_max'))} | "
            f"{f(c.get('converge_s'), 0)} | "
            f"{f(c.get('revisit_mean_s'), 0)} / {f(c.get('revisit_worst_s'), 0)} / "
            f"{f(c.get('revisit_ideal_s'), 0)} | {times(c.get('speedup'))} | "
            f"{f(c.get('wall_s'), 0)} |"
        )
    lines.append("")
    return "\n".join(lines)


def suite_figure(cases: list[dict[str, Any]], path: Path) -> None:
    """Grouped bars, log scale: our steady-state errors beside the thesis's, per case,
    with the goal (a fifth of the thesis's) marked over ours."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    labels = [f"{c.get('map')}\n{c.get('start')}" for c in cases]
    x = np.arange(len(cases))
    fig, axes = plt.subplots(2, 1, figsize=(max(8, 1.1 * len(cases)) + 2.5, 7), sharex=True)
    panels = (("phase_sse_rad", "thesis_phase_sse_rad", "phase steady-state error (rad)"),
              ("workload_sse_m2", "thesis_workload_sse_m2",
               "workload steady-state error (m^2)"))
    for ax, (key, thesis_key, title) in zip(axes, panels, strict=True):
        ours = [c.get(key) if isinstance(c.get(key), (int, float)) else np.nan for c in cases]
        theirs = [c.get(thesis_key, np.nan) for c in cases]
        ax.bar(x - 0.2, theirs, 0.4, label="thesis (tables 7.1, 7.2)", color="#bbbbbb")
        ax.bar(x + 0.2, np.maximum(np.asarray(ours, dtype=float), 1e-5), 0.4, label="ours",
               color="#1f77b4")
        ax.hlines(np.asarray(theirs, dtype=float) / 5.0, x, x + 0.4, colors="black",
                  linewidth=1.5, label="goal: a fifth of the thesis's")
        ax.set_yscale("log")
        ax.set_title(title)
        ax.grid(True, axis="y", alpha=0.3, which="both")
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
        ax.set_xlim(-0.6, len(cases) - 0.4)
    axes[-1].set_xticks(x, labels, fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
