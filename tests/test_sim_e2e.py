"""`btrack sim` end to end: world, recorder and three agents as real OS processes
over Zenoh on loopback; assertions on what landed in the recording and the report."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys

import pytest

from tests.procutil import end, end_children_of_run, pid_alive, run_sim, wait_for_world

SUMMARY_KEYS = {
    "map", "start", "robots", "localization", "seed", "duration_s", "speedup", "phase_sse_rad",
    "phase_sse_path_rad", "phase_max_rad", "workload_sse_m2", "workload_max_m2", "converge_s",
}


HALF_S = 400  # simulated seconds of the half-algae run: workload inside its band by ~200 s


@pytest.fixture(scope="module")
def half_algae_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "half"
    result = run_sim(out, "--robots", "3", "--map", "half-algae", "--start", "ahead:1",
                     "--localization", "truth", "--duration", str(HALF_S), "--seed", "3",
                     "--progress-every", "0.2", quiet=False)
    assert result.returncode == 0, result.stderr[-3000:]
    return out, result


def test_progress_lines_follow_the_run(half_algae_run):
    """The launcher's progress lines (from its queries to the recorder): simulated time
    going forward, the speed, the errors the agents see and who is alive."""
    _, result = half_algae_run
    # an error the recorder could not give at that moment is printed as n/a; the line
    # still counts. Under load the recorder hears the agents' states well ahead of the
    # world's ticks: the errors are then of that later time, which the line gives. A
    # line comes only when the recorder's time moved, so every speed shown is a real one
    pattern = re.compile(rf"^t = +([\d.]+) / {HALF_S} s +([\d.]+)x real time +\|e_phi\| "
                         r"(n/a|[\d.]+) rad +\|e_psi\| (n/a|[\d.]+) m\^2"
                         r"(?: \(agents at ([\d.]+) s\))? +live \[0, 1, 2\]$")
    lines = [m for m in map(pattern.match, result.stdout.splitlines()) if m]
    shown = [line for line in result.stdout.splitlines() if line.startswith("t =")]
    assert len(lines) >= 3, shown
    times = [float(m.group(1)) for m in lines]
    assert times == sorted(times) and times[-1] > times[0] and times[-1] <= HALF_S
    assert times == sorted(set(times)), shown  # each line is news
    assert all(float(m.group(2)) > 0 for m in lines[1:])
    # robot 1 starts 72 degrees ahead: the first known phase error is the larger
    phases = [float(m.group(3)) for m in lines if m.group(3) != "n/a"]
    assert len(phases) >= 2 and phases[0] > phases[-1], shown


def test_errors_shrink_half_algae_robot1_ahead(half_algae_run):
    out, _ = half_algae_run
    summary = json.loads((out / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(summary)
    assert summary["map"] == "half-algae" and summary["start"] == "ahead:1"
    assert summary["robots"] == 3 and summary["localization"] == "truth"
    # the bar: the last quarter's mean error under a quarter of the first's
    assert summary["phase_q4_rad"] < summary["phase_q1_rad"] / 4, summary
    assert summary["workload_q4_m2"] < summary["workload_q1_m2"] / 4, summary
    assert summary["phase_sse_rad"] < 0.169  # the thesis's in-phase half-algae cell
    assert summary["speedup"] > 0  # measured and quoted (how fast is the bench's business)
    assert summary["ticks"] == 10 * HALF_S  # every tick at 10 Hz is in the recording
    assert summary["invalid_messages"] == 0


def test_run_leaves_recording_report_and_no_process(half_algae_run):
    out, result = half_algae_run
    assert (out / "run.mcap").stat().st_size > 10_000
    for name in ("summary.json", "report.md", "errors.png", "map.png"):
        assert (out / name).exists(), name
    assert (out / "errors.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    pids = json.loads((out / "logs" / "pids.json").read_text())
    assert set(pids) == {"recorder", "world", "agent0", "agent1", "agent2"}
    assert not [name for name, pid in pids.items() if pid_alive(pid)]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_ctrl_c_or_sigterm_stops_every_process(tmp_path, sig):
    out = tmp_path / "interrupted"
    proc = subprocess.Popen(
        [sys.executable, "-m", "btrack", "sim", "--out", str(out), "--quiet",
         "--duration", "100000", "--no-report"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )
    try:
        pids = wait_for_world(out, proc)
        # the recorder (the team's router) is off the lockstep's path: it yields the cores
        lockstep = os.getpriority(os.PRIO_PROCESS, pids["world"])
        assert os.getpriority(os.PRIO_PROCESS, pids["agent1"]) == lockstep
        assert os.getpriority(os.PRIO_PROCESS, pids["recorder"]) > lockstep
        os.kill(proc.pid, sig)
        assert proc.wait(30) == 128 + sig
        assert not [name for name, pid in pids.items() if pid_alive(pid)]
    finally:
        end(proc)
        end_children_of_run(out)


def test_the_same_seed_gives_the_same_run_even_side_by_side(tmp_path):
    # two teams started at once on the same two cores: different timing, same run to
    # the last bit (the world's clock, neighbours followed from tick 0, states before
    # commands, and the world's settle before tick 0)
    outs = [tmp_path / "a", tmp_path / "b"]
    procs = [subprocess.Popen(
        [sys.executable, "-m", "btrack", "sim", "--robots", "3", "--map", "random-algae",
         "--start", "in-phase", "--localization", "truth", "--duration", "40", "--out",
         str(out), "--quiet", "--no-scene"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    ) for out in outs]
    try:
        for proc in procs:
            assert proc.wait(180) == 0, proc.communicate()[1][-3000:]
    finally:
        for proc, out in zip(procs, outs, strict=True):
            end(proc)
            end_children_of_run(out)
    from report.load import load_run

    runs = [load_run(out / "run.mcap") for out in outs]
    for i in range(3):
        a, b = runs[0].truth[i], runs[1].truth[i]
        assert a.t.size == b.t.size == 400
        assert (a.x == b.x).all() and (a.y == b.y).all() and (a.theta == b.theta).all()
        assert (runs[0].states[i].phase == runs[1].states[i].phase).all()


def test_odometry_noise_from_the_command_line_reaches_the_world_and_the_summary(tmp_path):
    # a gyro-grade heading (no turn noise) with noisy wheels: the poses the agents were
    # given keep the true heading but not the true position
    out = tmp_path / "gyro"
    result = run_sim(out, "--robots", "2", "--map", "no-algae", "--localization", "odometry",
                     "--odom-noise", "0.05", "--odom-turn-noise", "0", "--duration", "30",
                     timeout=180)
    assert result.returncode == 0, result.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["odom_noise"] == 0.05 and summary["odom_turn_noise"] == 0.0
    from report.load import load_run

    run = load_run(out / "run.mcap")
    for i in (0, 1):
        pose, truth = run.poses[i], run.truth[i]
        n = min(pose.t.size, truth.t.size)
        assert n >= 290 and (pose.t[:n] == truth.t[:n]).all()
        assert abs(pose.theta[:n] - truth.theta[:n]).max() < 1e-9
        assert abs(pose.x[:n] - truth.x[:n]).max() > 1e-4


def test_sim_refuses_a_negative_odometry_noise(tmp_path):
    result = run_sim(tmp_path / "bad", "--odom-turn-noise", "-0.1", timeout=60)
    assert result.returncode == 2
    assert "must be >= 0" in result.stderr and "Traceback" not in result.stderr
