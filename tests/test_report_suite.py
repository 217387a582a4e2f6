"""The suite's markdown (report.suite) from summaries, without running a suite."""

from __future__ import annotations

from report.suite import suite_markdown


def case(**kw: object) -> dict[str, object]:
    base: dict[str, object] = {
        "map": "no-algae", "start": "in-phase", "dir": "no-algae_in-phase",
        "phase_sse_rad": 0.01, "workload_sse_m2": 0.002, "phase_path_sse_rad": 0.031,
        "phase_sse_path_rad": 0.031, "phase_path_max_rad": 0.12, "phase_max_rad": 0.2,
        "workload_max_m2": 0.01, "workload_rel_sse": 0.0042, "workload_rel_max": 0.0125,
        "converge_s": 300.0, "revisit_mean_s": 60.0, "revisit_worst_s": 140.0,
        "revisit_ideal_s": 70.0, "speedup": 20.0, "wall_s": 60.0,
        "thesis_phase_sse_rad": 0.073, "thesis_workload_sse_m2": 0.010,
    }
    base.update(kw)
    return base


def other_measures(text: str) -> list[list[str]]:
    table = text.split("## Other measures (against truth)")[1]
    rows = [line for line in table.splitlines() if line.startswith("|")]
    return [[c.strip() for c in row.strip("|").split("|")] for row in rows]


def test_other_measures_quote_the_path_phase_and_the_relative_workload() -> None:
    older = case(start="ahead:1", dir="no-algae_ahead1")  # a summary from before the keys
    for key in ("phase_path_sse_rad", "phase_path_max_rad", "workload_rel_sse",
                "workload_rel_max"):
        del older[key]
    failed = {"map": "half-algae", "start": "in-phase", "dir": "x", "error": "crashed"}
    text = suite_markdown([case(), older, failed], {"suite": "thesis"}, 0, 0)
    header, rule, ours, old, broken = other_measures(text)
    assert len(rule) == len(header) == len(ours) == len(old) == len(broken)
    assert "phase, path length (rad)" in header and "phase, path length, max (rad)" in header
    row = dict(zip(header, ours, strict=True))
    assert row["phase, path length (rad)"] == "0.031"
    assert row["phase, path length, max (rad)"] == "0.120"
    assert row["workload / mean workload, steady state / max (%)"] == "0.42 / 1.25"
    assert row["revisit mean / worst / ideal (s)"] == "60 / 140 / 70"  # kept as it was
    row = dict(zip(header, old, strict=True))
    assert row["phase, path length (rad)"] == "0.031"  # from phase_sse_path_rad
    assert row["workload / mean workload, steady state / max (%)"] == "n/a / n/a"


def test_a_case_that_measured_nothing_prints_n_a_and_does_not_end_the_suite() -> None:
    """A case whose agent fell out of the run has no last quarter: its summary's errors
    are None, and the progress line said so by raising (the suite ended)."""
    from pathlib import Path

    from deploy.suite import Case, _progress

    case = Case("no-algae", "ahead:0", Path("x"))
    case.wall_s = 12.0
    line = _progress(case, 2, 12, {"phase_sse_rad": None, "thesis_phase_sse_rad": 0.093,
                                   "workload_sse_m2": None, "thesis_workload_sse_m2": 0.013})
    assert "phase n/a rad (thesis 0.093)" in line and "workload n/a m^2" in line
