"""``btrack suite thesis`` through its command: a short suite of two cases, each a
full multi-process team; the files it writes and the shape of the thesis's tables."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

from report.summary import KEYS
from report.thesis import START_HEADINGS
from tests.procutil import end, end_children_of_run, pid_alive, wait_for_world


def test_short_suite_writes_tables_summary_and_every_case(tmp_path: Path) -> None:
    out = tmp_path / "suite"
    proc = subprocess.Popen(
        [sys.executable, "-m", "btrack", "suite", "thesis", "--out", str(out),
         "--duration", "40", "--maps", "no-algae", "--starts", "in-phase", "ahead:1",
         "--jobs", "2", "--localization", "truth"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )
    case_dirs = [out / "no-algae_in-phase", out / "no-algae_ahead1"]
    try:
        stdout, stderr = proc.communicate(timeout=240)
    finally:
        end(proc)
        for case in case_dirs:
            end_children_of_run(case)
    assert proc.returncode == 0, stderr[-3000:]
    assert "[2/2]" in stdout and "report" in stdout

    doc = json.loads((out / "summary.json").read_text())
    assert doc["suite"] == "thesis" and doc["duration_s"] == 40
    cases = doc["cases"]
    assert [(c["map"], c["start"]) for c in cases] == [("no-algae", "in-phase"),
                                                       ("no-algae", "ahead:1")]
    for c in cases:
        assert set(KEYS) <= set(c)
        assert c["localization"] == "truth" and c["robots"] == 3
        assert c["ticks"] == 400  # 40 s at 10 Hz, every tick recorded
    # the thesis's cells: table 7.1 and 7.2, no algae, all in phase and robot 2 out
    assert cases[0]["thesis_phase_sse_rad"] == 0.073
    assert cases[1]["thesis_phase_sse_rad"] == 0.073
    assert cases[0]["thesis_workload_sse_m2"] == 0.010
    assert cases[1]["thesis_workload_sse_m2"] == 0.015

    assert doc["below_thesis"] in (0, 1, 2) and doc["below_thesis_agents"] in (0, 1, 2)
    for c in cases:  # with truth poses the agents' own view is the true one
        assert abs(c["phase_sse_agents_rad"] - c["phase_sse_rad"]) < 0.05

    text = (out / "report.md").read_text()
    assert "Table 7.1" in text and "Table 7.2" in text and "As the robots see it" in text
    tables = text.split("**Table 7.")[1:] + text.split("as the agents see it (")[1:]
    assert len(tables) == 4
    for table in tables:
        rows = [line for line in table.splitlines() if line.startswith("|")]
        header, rule, *body = rows
        assert header.count("|") == len(START_HEADINGS) + 2
        assert all(h in header for h in START_HEADINGS)
        assert len(body) >= 1 and body[0].startswith("| no-algae |")
        cells = [c.strip() for c in body[0].strip("|").split("|")][1:]
        assert len(cells) == 4 and cells[0] and cells[2] and not cells[1] and not cells[3]
        assert all(" / 0.0" in cells[i] for i in (0, 2))  # ours / thesis's
    assert (out / "suite.png").read_bytes()[:4] == b"\x89PNG"

    for case in case_dirs:
        for name in ("run.mcap", "report.md", "errors.png", "boundaries.png", "map.png",
                     "revisit.png"):
            assert (case / name).exists(), case / name
        pids = json.loads((case / "logs" / "pids.json").read_text())
        assert not [n for n, pid in pids.items() if pid_alive(pid)]


def test_sigterm_stops_the_suite_and_every_process_of_its_cases(tmp_path: Path) -> None:
    out = tmp_path / "suite"
    proc = subprocess.Popen(
        [sys.executable, "-m", "btrack", "suite", "thesis", "--out", str(out),
         "--duration", "100000", "--maps", "no-algae", "--starts", "in-phase", "--jobs", "1",
         "--localization", "truth", "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )
    case = out / "no-algae_in-phase"
    try:
        pids = wait_for_world(case, proc)
        os.kill(proc.pid, signal.SIGTERM)
        # read its pipes while it stops (wait() alone deadlocks once it has written more
        # than a pipe holds); its case's launcher has 30 s to end its team before a kill
        _, err = proc.communicate(timeout=90)
        assert proc.returncode == 128 + signal.SIGTERM, err[-2000:]
        assert "terminated" in err
        assert not [name for name, pid in pids.items() if pid_alive(pid)]
    finally:
        end(proc)
        end_children_of_run(case)


def test_in_process_thesis_suite_gives_the_tables_in_seconds(tmp_path: Path) -> None:
    """``--engine inprocess``: the same cases with the same cores, no processes; the
    table quotes both phases and the relative workload. pf needs the localizer
    process, so it is refused by name."""
    out = tmp_path / "suite"
    res = subprocess.run(
        [sys.executable, "-m", "btrack", "suite", "thesis", "--engine", "inprocess",
         "--maps", "half-algae", "no-algae", "--starts", "ahead:1", "--duration", "700",
         "--jobs", "2", "--out", str(out)],
        capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    doc = json.loads((out / "summary.json").read_text())
    assert doc["engine"] == "inprocess" and len(doc["cases"]) == 2
    half = next(c for c in doc["cases"] if c["map"] == "half-algae")
    for key in ("phase_sse_rad", "phase_path_sse_rad", "workload_sse_m2", "workload_rel_sse"):
        assert isinstance(half[key], float), key
    assert half["thesis_phase_sse_rad"] == 0.206
    report = (out / "report.md").read_text()
    assert "half-algae" in report and "0.206" in report
    # no case directory is written, so none is linked; the speed-up is measured
    assert "/report.md)" not in report and "n/ax" not in report
    assert half["speedup"] > 1 and "dir" not in half
    bad = subprocess.run([sys.executable, "-m", "btrack", "suite", "thesis", "--engine",
                          "inprocess", "--localization", "pf", "--out", str(tmp_path / "x")],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "use --engine bus" in bad.stderr
