"""The general suite's outputs: summary.json, report.md with every measure of every
case against the goals, and general.png, the errors against team size and edge
length."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from report.summary import json_safe  # noqa: E402

Goal = tuple[str, str, float, str]

# The columns of the table: key, heading, format spec ("%" for a fraction shown as %)
COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("phase_sse_rad", "position phase rad", ".4f"),
    ("phase_path_sse_rad", "path phase rad", ".3f"),
    ("workload_sse_m2", "workload m^2", ".4f"),
    ("workload_rel_sse", "workload %", "%"),
    ("workload_sse_agents_m2", "believed m^2", ".4f"),
    ("revisit_mean_s", "revisit mean s", ".0f"),
    ("revisit_std_s", "std s", ".0f"),
    ("revisit_worst_s", "worst s", ".0f"),
    ("revisit_optimum_s", "optimum s", ".0f"),
    ("revisit_worst_ratio", "worst/optimum", ".2f"),
    ("still_frac_max", "still", ".2f"),
    ("workload_rel_converge_s", "workload in band s", ".0f"),
    ("cycle_s", "cycle s", ".0f"),
)


def _fmt(value: Any, fmt: str) -> str:
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        return "n/a"
    return f"{100 * value:.2f}" if fmt == "%" else format(value, fmt)


def write_general_report(out: Path, rows: list[dict[str, Any]], settings: dict[str, Any],
                         goals: tuple[Goal, ...]) -> int:
    """Write out/summary.json, out/report.md and out/general.png; return how many cases
    meet every goal."""
    met_all = sum(1 for r in rows if r.get("goals") and all(r["goals"].values()))
    per_goal = {name: sum(1 for r in rows if r.get("goals", {}).get(name)) for name, *_ in goals}
    worst = {key: _worst(rows, key) for _, key, _, _ in goals}
    doc = {**settings, "meet_every_goal": met_all, "meet_goal": per_goal, "worst": worst,
           "goals": [{"name": n, "key": k, "bound": b, "unit": u} for n, k, b, u in goals],
           "cases": rows}
    (out / "summary.json").write_text(json.dumps(json_safe(doc), indent=2, allow_nan=False)
                                      + "\n")
    general_figure(rows, out / "general.png", goals)
    (out / "report.md").write_text(markdown(rows, settings, goals, met_all, per_goal, worst))
    return met_all


def _worst(rows: list[dict[str, Any]], key: str) -> float:
    values = [r[key] for r in rows if isinstance(r.get(key), (int, float))
              and math.isfinite(r[key])]
    return max(values) if values else math.nan


def markdown(rows: list[dict[str, Any]], settings: dict[str, Any], goals: tuple[Goal, ...],
             met_all: int, per_goal: dict[str, int], worst: dict[str, float]) -> str:
    n = len(rows)
    lines = [
        "# General suite: random maps, team sizes and starts",
        "",
        ", ".join(f"{k} {v}" for k, v in settings.items()),
        "",
        f"**{met_all} of {n} cases meet every goal.** Steady state is the mean |e| over "
        "neighbour pairs and the last quarter of each run; workload from the map's true "
        "patrol depth (\"believed\": from the workloads the agents published); revisit over "
        "the second half, against the partition optimum 2 L / (n v) for the team's "
        "measured along-edge speed.",
        "",
        "| goal | bound | cases that meet it | worst case |",
        "| --- | --- | --- | --- |",
    ]
    for name, key, bound, unit in goals:
        shown = "" if key == "workload_belief_gap_m2" else f"{bound:g}"
        lines.append(f"| {name} | {shown} {unit} | {per_goal[name]} of {n} | "
                     f"{_fmt(worst[key], '.4f')} |")
    lines += ["", "## Every case", "",
              "| case | robots | edge m | shape | algae | start | s | "
              + " | ".join(h for _, h, _ in COLUMNS) + " | goals missed |",
              "| " + " | ".join(["---"] * (8 + len(COLUMNS))) + " |"]
    for r in rows:
        missed = [g for g, ok in r.get("goals", {}).items() if not ok]
        lines.append(
            f"| {r['index']} | {r['robots']} | {r['length_m']:.1f} | {r['edge']} | "
            f"{r['algae']} | {r['start']} | {r['duration_s']:.0f} | "
            + " | ".join(_fmt(r.get(k), f) for k, _, f in COLUMNS)
            + f" | {', '.join(missed) if missed else '-'}"
            + (f" (error: {r['error']})" if "error" in r else "") + " |")
    lines += ["", "Maps (each a `btrack sim --map` name):", ""]
    lines += [f"- {r['index']}: `{r['map']}`, seed {r['seed']}" for r in rows]
    return "\n".join(lines) + "\n"


BELIEF_KEY = "workload_belief_gap_m2"


def general_figure(rows: list[dict[str, Any]], path: Path, goals: tuple[Goal, ...]) -> None:
    """Each goal's measure against team size (left) and edge length (right), the goal's
    bound dashed; for the agents' own workload, the true workload error and the one the
    agents believed, against the goal's floor."""
    shown = [g for g in goals if g[1] != BELIEF_KEY]
    belief = next((g for g in goals if g[1] == BELIEF_KEY), None)
    panels = len(shown) + (belief is not None)
    fig, axes = plt.subplots(panels, 2, figsize=(10, 2.3 * panels), squeeze=False)
    if belief is not None:
        _belief_panel(rows, belief[0], axes[-1])
    for (name, key, bound, unit), (left, right) in zip(shown, axes, strict=False):
        ys = [r.get(key, math.nan) for r in rows]
        ok = [r.get("goals", {}).get(name, False) for r in rows]
        _met_and_missed(rows, (left, right), ys, ok, bound, name, ("met", "missed"))
        left.set_title(f"{name} ({unit}); dashed: the goal", fontsize=8, loc="left")
    axes[0][1].legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _met_and_missed(rows: list[dict[str, Any]], pair: Any, ys: list[float], ok: list[bool],
                    bound: float, ylabel: str, labels: tuple[str, str]) -> None:
    """``ys`` against team size (``pair[0]``) and edge length (``pair[1]``): the cases
    that met the goal as dots, those that missed it as red crosses, ``bound`` dashed."""
    for ax, xs, label in ((pair[0], [r["robots"] for r in rows], "robots"),
                          (pair[1], [r["length_m"] for r in rows], "edge length, m")):
        ax.scatter([x for x, g in zip(xs, ok, strict=True) if g],
                   [y for y, g in zip(ys, ok, strict=True) if g], s=14, color="tab:blue",
                   label=labels[0])
        ax.scatter([x for x, g in zip(xs, ok, strict=True) if not g],
                   [y for y, g in zip(ys, ok, strict=True) if not g], s=18,
                   color="tab:red", marker="x", label=labels[1])
        ax.axhline(bound, color="k", linestyle="--", linewidth=0.8)
        ax.set_xlabel(label)
        ax.set_ylabel(ylabel, fontsize=8)
        if label == "robots":
            ax.set_xticks(sorted({r["robots"] for r in rows}))


def _belief_panel(rows: list[dict[str, Any]], name: str, pair: Any) -> None:
    """The true workload error of each case (met or missed: the agents' own within 20 %
    of it or 0.002 m^2) and the error the agents believed, on a log scale."""
    floor = 1e-6  # a case at 0 drawn on the axis's floor
    true = [max(floor, r.get("workload_sse_m2", math.nan)) for r in rows]
    believed = [max(floor, r.get("workload_sse_agents_m2", math.nan)) for r in rows]
    ok = [r.get("goals", {}).get(name, False) for r in rows]
    for ax, xs in ((pair[0], [r["robots"] for r in rows]),
                   (pair[1], [r["length_m"] for r in rows])):
        ax.scatter(xs, believed, s=12, facecolors="none", edgecolors="tab:gray",
                   label="believed by the agents")
        ax.set_yscale("log")
    _met_and_missed(rows, pair, true, ok, 0.002, "workload error, m^2",
                    ("true, believed within the goal", "true, believed outside it"))
    pair[0].set_title(f"{name}: true workload error (m^2) and the agents' own; dashed: "
                      "the goal's floor, 0.002 m^2", fontsize=8, loc="left")
    pair[1].legend(fontsize=7, loc="lower right")
