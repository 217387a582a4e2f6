"""A real team under the lab sensor profile (``btrack sim --sensors lab``): the localizer
keeps every robot's identity at every scan while a person walks through the team, and
every robot's mean error stays at or under 2 cm."""

from __future__ import annotations

import numpy as np

from report.load import load_run
from simworld.maps import ROBOT_ROOM_M, builtin_map
from simworld.sensors import SensorProfile, Walker
from tests.identity import check_identities, truth_at_ticks
from tests.procutil import run_sim

DURATION_S = 60.0


def test_identity_kept_with_a_person_walking_among_the_robots(tmp_path) -> None:
    out = tmp_path / "lab"
    sim = run_sim(out, "--robots", "3", "--localization", "pf", "--sensors", "lab",
                  "--map", "half-algae", "--start", "ahead:1", "--duration", str(DURATION_S),
                  "--no-report")
    assert sim.returncode == 0, sim.stderr[-3000:]
    # the agents are told the profile's sensors, which they place their edges back for
    for i in range(3):
        log = (out / "logs" / f"agent{i}.log").read_text()
        assert "placed back for 0.05 s of latency and a 0.02 m dead band" in log, log[-500:]
    run = load_run(out)
    ids = run.robot_ids
    assert ids == [0, 1, 2]
    check_identities(run, ids, int(0.95 * DURATION_S * 10), max_m=0.06, mean_m=0.02)
    t, truth = truth_at_ticks(run, ids)
    # the check is worth something only if the person did walk among them: a leg came
    # within half a metre of a robot, more than once
    p = SensorProfile()
    gmap = builtin_map("half-algae")
    walker = Walker(gmap.edge_lo, gmap.edge_hi, -ROBOT_ROOM_M + 0.4, 0.9, p.person_speed,
                    p.leg_radius_m, p.stride_m, p.step_s)
    legs = walker.legs(t)  # (ticks, 2, 2)
    close = np.zeros(t.size, dtype=bool)
    for i in ids:
        for k in range(2):
            close |= np.hypot(*(legs[:, k] - truth[i]).T) < 0.5
    assert close.sum() >= 20
