"""``btrack sim --hil`` end to end, briefly: every process of the hardware stack runs
against emulated devices on pseudo-terminals, the recording is written, and the run's
hil.json (merged into summary.json when there is a report) says hil and counts the
serial errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from tests.procutil import end_children_of_run


def test_sim_hil_short_run(tmp_path: Path) -> None:
    out = tmp_path / "hil"
    try:
        res = subprocess.run(
            [sys.executable, "-m", "btrack", "sim", "--hil", "--duration", "6", "--out",
             str(out), "--quiet", "--no-report", "--hil-faults", "0.02",
             "--map", "procedural:7,length=5,algae=steps"],
            capture_output=True, timeout=180)
    finally:
        end_children_of_run(out)
    assert res.returncode == 0, res.stderr.decode()[-2000:]
    summary = json.loads((out / "hil.json").read_text())
    assert summary["hil"] is True
    assert set(summary["serial_errors"]) == {"bridge0", "bridge1", "bridge2", "bridge-lms"}
    assert summary["faults_injected"] > 0 and summary["serial_errors_total"] > 0
    assert summary["port_losses"] == 0  # the devices outlive the bridges at the end
    assert summary["scan_rate_hz"] > 0 and summary["world"]["ticks"] > 30
    # every tick of the run recorded, the done one too, so the recorder ended by itself
    # (its ticks count from the epoch: it once refused all after duration / dt)
    recorder = json.loads((out / "logs" / "recorder.out").read_text().splitlines()[-1])
    assert recorder["done"] and recorder["rejected"] == 0, recorder
    assert recorder["ticks"] == summary["world"]["ticks"], (recorder, summary["world"])
    assert (out / "run.mcap").stat().st_size > 0
    # the recording names the map in full, so the report (or a rerun) rebuilds it
    from report.load import load_run

    run = load_run(out)
    info = run.info
    assert info["map"].startswith("procedural:7,length=5") and "edge=" in info["map"]
    for i in range(3):
        agent = json.loads((out / "logs" / f"agent{i}.out").read_text().splitlines()[-1])
        assert agent["ticks"] > 10  # the agents ran on the bridges' sensing
    # ... and on the particle filter's poses from the LMS bridge's scans, at their
    # measured times (issue 23, item 1); the world sent only Truth
    assert info["localization"] == "pf"
    localizer = json.loads((out / "logs" / "localizer.out").read_text().splitlines()[-1])
    assert localizer["timing"] == "measured" and localizer["scans"] >= 10
    for i in range(3):
        truth, pose = run.truth[i], run.poses[i]
        at = np.searchsorted(truth.t, pose.t).clip(0, truth.t.size - 1)
        near = np.abs(truth.t[at] - pose.t) < 1e-6
        assert near.sum() > 10
        err = np.hypot(pose.x[near] - truth.x[at][near], pose.y[near] - truth.y[at][near])
        assert np.median(err) < 0.05, (i, np.median(err))
