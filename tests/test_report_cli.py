"""``btrack report`` on a synthetic run written through the recorder's own writer."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from recorder.writer import Recording, RunWriter
from report.faults import coverage
from report.load import load_run
from report.measures import speedup
from report.series import time_grid
from report.summary import KEYS
from report.synthetic import write_synthetic_run
from wire.codec import encode
from wire.messages import Tick

PNG = b"\x89PNG\r\n\x1a\n"
ROOT = Path(__file__).resolve().parents[1]


def btrack(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "btrack", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_report_writes_summary_figures_and_markdown(tmp_path: Path) -> None:
    write_synthetic_run(tmp_path, duration_s=60.0, garbage=3)
    done = btrack("report", str(tmp_path))
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert tuple(summary) == KEYS
    figures = ("errors.png", "boundaries.png", "map.png", "revisit.png")
    for name in figures:
        assert (tmp_path / name).read_bytes()[:8] == PNG
    text = (tmp_path / "report.md").read_text()
    assert all(name in text for name in figures)
    assert summary["map"] == "synthetic" and summary["robots"] == 3
    assert summary["ticks"] == 601
    assert summary["invalid_messages"] == 3
    assert summary["speedup"] == pytest.approx(100.0, rel=1e-3)
    # the synthetic offset of 2 pi / 5 decays with an 8 s time constant: inside the
    # 0.15 rad band after 8 ln(1.2566 / 0.15) = 17.0 s, near zero by the last quarter
    # e = A exp(-t / 8) averaged over the trailing 10 s is A (8/10) (e^(10/8) - 1) exp(-t / 8)
    smoothed_gain = 0.8 * (math.exp(10 / 8) - 1)
    assert summary["phase_converge_s"] == pytest.approx(
        8 * math.log(2 * math.pi / 5 * smoothed_gain / 0.15), abs=0.2
    )
    assert summary["phase_sse_rad"] < 0.01
    assert summary["phase_q1_rad"] > 0.3
    # half-algae depth with equal segments: true workloads 2.4, 1.2 + 0.6... pairs -1.2 m^2
    assert summary["workload_sse_m2"] == pytest.approx(1.2, abs=1e-6)
    assert summary["workload_converge_s"] is None and summary["converge_s"] is None
    assert summary["revisit_ideal_s"] > 0


def test_errors_as_the_agents_see_them_come_from_what_they_published(tmp_path: Path) -> None:
    # robot 1 publishes a phase 0.2 rad ahead of where it is, and every agent the same
    # workload (0.9 m deep everywhere, against the map's 1.5 / 0.3 m)
    write_synthetic_run(tmp_path, duration_s=60.0, phase_bias=(0.0, 0.2, 0.0))
    done = btrack("report", str(tmp_path))
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["phase_sse_rad"] < 0.01  # truth: the offset has decayed
    assert summary["phase_sse_agents_rad"] == pytest.approx(0.2, abs=0.01)  # both pairs
    assert summary["workload_sse_m2"] == pytest.approx(1.2, abs=1e-6)
    assert summary["workload_sse_agents_m2"] == pytest.approx(0.0, abs=1e-9)
    text = (tmp_path / "report.md").read_text()
    assert "as the agents see it" in text


def test_a_hardware_recording_is_measured_from_the_agents_poses(tmp_path: Path) -> None:
    # no world: no WorldInfo, Tick or ground truth; the localizer's poses and the states
    sim, hw = tmp_path / "sim", tmp_path / "hw"
    write_synthetic_run(sim, duration_s=60.0)
    write_synthetic_run(hw, duration_s=60.0, hardware=True)
    for d in (sim, hw):
        done = btrack("report", str(d))
        assert done.returncode == 0, done.stderr
    ours, ref = (json.loads((d / "summary.json").read_text()) for d in (hw, sim))
    assert (ours["positions_from"], ref["positions_from"]) == ("poses", "truth")
    assert ours["ticks"] == 0 and ours["map"] is None
    # the poses are where the robots were: the same position-based measures as truth
    for key in ("phase_q1_rad", "phase_sse_rad", "revisit_mean_s", "phase_sse_agents_rad"):
        assert ours[key] is not None and ours[key] == pytest.approx(ref[key], rel=0.05), key
    assert ours["phase_q1_rad"] > 0.1  # the decaying offset is seen
    assert ours["workload_sse_m2"] is None  # no true patrol depth without a world
    assert ours["workload_sse_agents_m2"] == pytest.approx(0.0, abs=1e-9)
    # the edge comes from the agents' states: the segments' coverage is measured too
    hw_run = load_run(hw / "run.mcap")
    gap, overlap = coverage(hw_run, time_grid(hw_run))
    assert gap.size and np.all(gap == 0.0) and np.all(overlap == 0.0)
    assert "No ground truth in this recording" in (hw / "report.md").read_text()
    assert "No ground truth" not in (sim / "report.md").read_text()


def test_wall_time_is_the_worlds_clock_when_the_ticks_carry_it(tmp_path: Path) -> None:
    # a recorder that took the ticks late and in a burst (log times 1 ms apart) must not
    # change the speed: the world stamped them 10 ms apart, 10x real time at 10 Hz
    writer = RunWriter(tmp_path / "run.mcap")
    rec = Recording(writer)
    for k in range(101):
        tick = Tick(t=k * 0.1, k=k, live=[0], done=k == 100, wall_ns=10**18 + k * 10**7)
        rec.handle("world/tick", encode(tick), 2 * 10**18 + k * 10**6)
    writer.close()
    run = load_run(tmp_path / "run.mcap")
    assert speedup(run.tick_t, run.tick_log_ns) == pytest.approx(10.0)


def test_make_report_returns_the_summary(tmp_path: Path) -> None:
    from report.cli import make_report

    write_synthetic_run(tmp_path, duration_s=10.0)
    summary = make_report(tmp_path)
    assert summary == json.loads((tmp_path / "summary.json").read_text())


def test_missing_recording_is_a_clear_error(tmp_path: Path) -> None:
    done = btrack("report", str(tmp_path / "nowhere"))
    assert done.returncode == 2
    assert "no recording" in done.stderr and "Traceback" not in done.stderr


def test_unreadable_recording_is_a_clear_error(tmp_path: Path) -> None:
    (tmp_path / "run.mcap").write_bytes(b"\x89MCAP0\r\n" + b"garbage" * 10)
    done = btrack("report", str(tmp_path))
    assert done.returncode == 2
    assert "cannot read" in done.stderr and "Traceback" not in done.stderr
