"""A team over the bus on a map that changes (issue 18): the world tells the recorder the
true depth as it changes, the report measures by it and marks the change, and the
in-process engine runs the same team bit for bit."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from deploy.engine import EngineCase, change_measures
from deploy.engine import run as run_case
from report.load import load_run
from tests.procutil import run_sim

CHANGE = "grow:0.5@0-20"


def test_a_bus_run_records_the_change_and_the_engine_is_it_bit_for_bit(tmp_path: Path
                                                                       ) -> None:
    out = tmp_path / "bus"
    sim = run_sim(out, "--robots", "3", "--map", "half-algae", "--localization", "truth",
                  "--duration", "30", "--change", CHANGE)
    assert sim.returncode == 0, sim.stderr[-3000:]
    run = load_run(out)
    times = [t for t, _ in run.depth_frames]
    assert times == pytest.approx([float(s) for s in range(21)])  # a frame a second
    first, last = run.depth_frames[0][1], run.depth_frames[-1][1]
    assert first[:300] == pytest.approx([1.5] * 300) and first[300:] == [0.3] * 300
    assert last[:300] == pytest.approx([2.25] * 300) and last[300:] == [0.3] * 300
    assert run.info["change"] == CHANGE and run.info["change_windows"] == [0.0, 20.0]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["change"] == CHANGE and summary["rejected_messages"] == 0
    (row,) = summary["changes"]
    assert (row["t0"], row["t1"]) == (0.0, 20.0) and row["cycle_s"] > 0
    assert "## The map changed" in (out / "report.md").read_text()
    assert (out / "errors.png").stat().st_size > 0
    # the same team in one process: the same tracks, and the same true workload
    gmap, tracks = run_case(EngineCase(map="half-algae", robots=3, start="ahead:1",
                                       duration_s=30.0, seed=1, localization="truth",
                                       change=(CHANGE,)))
    for i in range(3):
        assert np.array_equal(run.truth[i].x, tracks.x[i])
        assert np.array_equal(run.truth[i].y, tracks.y[i])
    assert tracks.frame_t == pytest.approx(times)
    _, rows = change_measures(gmap, tracks)
    assert rows[0]["cycle_s"] == pytest.approx(row["cycle_s"])
    assert rows[0]["peak_rel"] == pytest.approx(row["peak_rel"], rel=1e-6)
