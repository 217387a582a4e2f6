"""The thesis's simulated results (tables 7.1 and 7.2): steady-state phase and
workload error of twelve cases, three maps by four starts, and the tables that put
our values beside them. Pure: summaries in, markdown out."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

MAPS = ("no-algae", "half-algae", "random-algae")
# The thesis numbers its robots from 1: its "robot K initially out of phase" is our
# ahead:K-1 (robot K-1 started 72 degrees ahead).
STARTS = ("in-phase", "ahead:0", "ahead:1", "ahead:2")
START_HEADINGS = (
    "all robots initially in phase",
    "robot 1 initially out of phase",
    "robot 2 initially out of phase",
    "robot 3 initially out of phase",
)

# Table 7.1, phase steady-state error (rad); rows MAPS, columns STARTS.
PHASE_SSE_RAD = {
    "no-algae": (0.073, 0.093, 0.073, 0.073),
    "half-algae": (0.169, 0.189, 0.206, 0.207),
    "random-algae": (0.222, 0.240, 0.257, 0.238),
}
# Table 7.2, workload steady-state error (m^2).
WORKLOAD_SSE_M2 = {
    "no-algae": (0.010, 0.013, 0.015, 0.012),
    "half-algae": (0.015, 0.015, 0.016, 0.019),
    "random-algae": (0.037, 0.036, 0.043, 0.043),
}


def thesis_cell(table: Mapping[str, Sequence[float]], map_name: str, start: str) -> float:
    """The thesis's value for one case, NaN for a case it did not run."""
    if map_name not in table or start not in STARTS:
        return math.nan
    return float(table[map_name][STARTS.index(start)])


def all_cases() -> list[tuple[str, str]]:
    """The twelve cases of tables 7.1 and 7.2, row by row."""
    return [(m, s) for m in MAPS for s in STARTS]


def _cell(ours: Any, theirs: float) -> str:
    if not isinstance(ours, (int, float)) or not math.isfinite(ours):
        return f"failed / {theirs:.3f}"
    ratio = theirs / ours if ours > 0 else math.inf
    ratio_text = ">1000" if ratio > 1000 else f"{ratio:.1f}"
    mark = "" if ours < theirs else " **not below**"
    return f"{ours:.4f} / {theirs:.3f} ({ratio_text}x){mark}"


def thesis_table(
    cases: Sequence[Mapping[str, Any]], key: str, table: Mapping[str, Sequence[float]],
    title: str,
) -> list[str]:
    """One table in the thesis's layout (maps down, starts across), each cell
    'ours / thesis (thesis over ours)'. Cases not run leave their cell empty."""
    by_case = {(c.get("map"), c.get("start")): c for c in cases}
    lines = [f"**{title}**", "", "| map | " + " | ".join(START_HEADINGS) + " |",
             "| --- |" + " --- |" * len(STARTS)]
    for map_name in MAPS:
        cells = []
        for start in STARTS:
            case = by_case.get((map_name, start))
            cells.append("" if case is None else
                         _cell(case.get(key), thesis_cell(table, map_name, start)))
        if any(cells):
            lines.append(f"| {map_name} | " + " | ".join(cells) + " |")
    return lines


TRUE_KEYS = ("phase_sse_rad", "workload_sse_m2")  # measured against ground truth
AGENT_KEYS = ("phase_sse_agents_rad", "workload_sse_agents_m2")  # as the robots see it


def below_thesis(case: Mapping[str, Any], keys: tuple[str, str] = TRUE_KEYS
                 ) -> tuple[bool, bool]:
    """Whether a case's phase and workload steady-state errors (``keys``: true or as the
    agents see them) are below the thesis's."""
    out = []
    for key, table in ((keys[0], PHASE_SSE_RAD), (keys[1], WORKLOAD_SSE_M2)):
        ours = case.get(key)
        theirs = thesis_cell(table, str(case.get("map")), str(case.get("start")))
        out.append(isinstance(ours, (int, float)) and math.isfinite(ours) and ours < theirs)
    return out[0], out[1]
