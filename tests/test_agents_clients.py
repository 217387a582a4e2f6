"""``btrack sim`` with a team of 10 or more: its agents are clients of the team's router
(one link each) rather than peers linked to each other, and the run is the same run:
the in-process engine's tracks bit for bit, every state of every robot in the recording
(the peer mesh's recorder missed up to 1 % of them at 50 robots; BENCHMARKS.md)."""

from __future__ import annotations

import json

import numpy as np

from deploy.engine import EngineCase, run
from report.load import load_run
from tests.procutil import run_sim

MAP = "procedural:3,length=9,edge=curved,amplitude=0.3,algae=steps"
ROBOTS, DURATION_S = 12, 8


def test_a_team_of_twelve_runs_as_clients_of_the_router_and_is_the_same_run(tmp_path):
    out = tmp_path / "run"
    sim = run_sim(out, "--robots", str(ROBOTS), "--map", MAP, "--start", "ahead:5",
                  "--duration", str(DURATION_S), "--localization", "truth", "--no-report",
                  "--seed", "4", timeout=240)
    assert sim.returncode == 0, sim.stderr[-3000:]
    assert json.loads((out / "bus.json").read_text())["agents"] == "client"
    recorded = load_run(out)
    ticks = 10 * DURATION_S
    assert sorted(recorded.states) == list(range(ROBOTS))
    assert all(len(s.t) == ticks for s in recorded.states.values()), {
        i: len(s.t) for i, s in recorded.states.items()}
    _, tracks = run(EngineCase(map=MAP, robots=ROBOTS, start="ahead:5", duration_s=DURATION_S,
                               seed=4))
    for i in range(ROBOTS):
        truth = recorded.truth[i]
        assert np.array_equal(truth.x[:ticks], tracks.x[i])
        assert np.array_equal(truth.y[:ticks], tracks.y[i])
    assert np.ptp(tracks.x) > 0.1  # the team moved along the edge
