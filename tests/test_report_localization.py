"""The report's localisation measures: odometry dead-reckoned from recorded sensing is
the world's own odometry pose; errors against truth on the ticks."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np

from report.load import RunData, Truth
from report.localization import dead_reckon, localization_errors, summary_stats
from simworld.maps import builtin_map
from simworld.world import World


def test_dead_reckoning_matches_the_worlds_odometry_pose() -> None:
    world = World(builtin_map("no-algae"), 1, seed=4, odom_noise=0.05)
    x0, y0, th0 = world.truth(0)
    dist, dth, expected = [], [], []
    for k in range(300):
        r = world.sense(0)
        dist.append(r.odom_dist_m)
        dth.append(r.odom_dtheta)
        expected.append(world.odometry_pose(0)[:2])
        world.step({0: (0.4, 0.6 * math.sin(0.05 * k))}, 0.1)
    x, y = dead_reckon(x0, y0, th0, np.array(dist), np.array(dth))
    assert np.allclose(np.stack([x, y], axis=1), np.array(expected), atol=1e-9)


def test_errors_against_truth_on_the_ticks() -> None:
    t = np.arange(5) * 0.1
    truth = Truth(t, np.zeros(5), np.zeros(5), np.zeros(5))
    poses = Truth(t[1:], np.full(4, 0.03), np.full(4, 0.04), np.zeros(4))  # no pose at t=0
    odometry = np.stack([t, np.full(5, 0.01), np.zeros(5)])  # drives 1 cm per tick along x
    run = RunData(info={}, tick_t=t, tick_log_ns=np.zeros(5, dtype=np.int64),
                  truth={0: truth}, poses={0: poses}, odometry={0: odometry})
    loc = localization_errors(run)
    assert np.isnan(loc.pf[0][0]) and np.allclose(loc.pf[0][1:], 0.05)
    assert np.allclose(loc.odometry[0], [0.0, 0.01, 0.02, 0.03, 0.04])
    mean, p95 = summary_stats(loc.pooled("pf"))
    assert math.isclose(mean, 0.05) and math.isclose(p95, 0.05)
    assert all(math.isnan(v) for v in summary_stats(np.empty(0)))


def test_a_robot_outside_the_team_steers_by_no_pose() -> None:
    """A joiner parked until tick 3: whatever the localizer said of it before, no
    agent used it."""
    t = np.arange(5) * 0.1
    truth = Truth(t, np.zeros(5), np.zeros(5), np.zeros(5))
    poses = Truth(t, np.full(5, 3.0), np.zeros(5), np.zeros(5))  # 3 m off throughout
    run = RunData(info={}, tick_t=t, tick_log_ns=np.zeros(5, dtype=np.int64),
                  truth={0: truth, 1: truth}, poses={0: poses, 1: poses},
                  tick_live=[[0], [0], [0], [0, 1], [0, 1]])
    loc = localization_errors(run)
    assert np.allclose(loc.pf[0], 3.0)
    assert np.isnan(loc.pf[1][:3]).all() and np.allclose(loc.pf[1][3:], 3.0)


def test_world_refuses_a_bad_kidnap() -> None:
    run = subprocess.run([sys.executable, "-m", "btrack", "world", "--kidnap", "1@x:1,0",
                          "--no-multicast"], capture_output=True, text=True, timeout=30)
    assert run.returncode == 2 and "ROBOT@T:DX,DY" in run.stderr
