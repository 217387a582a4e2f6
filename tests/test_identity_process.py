"""The localizer keeps who is who through a join, as processes on the bus: the issue's
``btrack sim --robots 3 --localization pf --fault join:3@T`` (the joiner parked in view
from the start, robot 1 hidden behind it), checked against truth at every scan."""

from __future__ import annotations

import numpy as np

from report.load import load_run
from tests.identity import truth_at_ticks
from tests.procutil import run_sim

JOIN_S, DURATION_S = 30.0, 50.0
SETTLED_S = 0.5  # the first scans cannot tell robot 1 from the parked joiner


def test_a_robot_hidden_behind_a_parked_joiner_is_not_taken_for_it(tmp_path) -> None:
    out = tmp_path / "join"
    sim = run_sim(out, "--robots", "3", "--localization", "pf", "--fault",
                  f"join:3@{JOIN_S:g}", "--duration", f"{DURATION_S:g}", "--no-report")
    assert sim.returncode == 0, sim.stderr[-3000:]
    run = load_run(out)
    ids = run.robot_ids
    assert ids == [0, 1, 2, 3]
    t, truth = truth_at_ticks(run, ids)
    est = np.stack([np.stack([np.interp(t, run.poses[i].t, run.poses[i].x),
                              np.interp(t, run.poses[i].t, run.poses[i].y)], axis=1)
                    for i in ids])
    d = np.hypot(est[:, None, :, 0] - truth[None, :, :, 0],
                 est[:, None, :, 1] - truth[None, :, :, 1])  # (estimate, truth, tick)
    after = t >= SETTLED_S
    nearest = d.argmin(axis=1)  # (estimate, tick)
    for n in (0, 2, 3):  # robot 1 is hidden behind the joiner until it drives out
        wrong = np.flatnonzero(after & (nearest[n] != n))
        assert wrong.size == 0, f"robot {ids[n]} nearest another robot at t = {t[wrong][:10]}"
    own = d[np.arange(len(ids)), np.arange(len(ids))]  # (robot, tick)
    parked = after & (t < JOIN_S)
    assert (own[3, parked] < 0.01).all()  # the joiner on its parked spot from the start
    assert (own[3, after] < 0.1).all()  # and followed once it drives
    assert (own[1, t < 10.0] > 0.3).all()  # robot 1 was hidden: the check is worth something
    assert (own[:, t > DURATION_S - 5.0] < 0.05).all()  # every robot found at the end
    assert (own[[0, 2]][:, after] < 0.05).all()
