"""Process tests of ``btrack localizer`` and of the whole team with ``--localization pf``:
real OS processes on a private namespace over loopback, real scans on the bus."""

from __future__ import annotations

import json
import math
import queue
from pathlib import Path

import numpy as np
import pytest

from report.load import load_run
from report.localization import localization_errors
from simworld.laser import Laser, Scanner
from tests.procutil import (
    end,
    end_children_of_run,
    free_port,
    hub_session,
    member_args,
    start,
    unique_ns,
    wait_for,
)
from wire import Keys, Pose, Scan, Sense, decode, encode
from wire.session import declare_publisher


@pytest.mark.parametrize("scanners, truth", [
    ([Scanner(3.0, -2.0)], [(1.0, -1.0), (4.5, -1.0)]),
    # a row of two, 14 m apart: each robot is in the range of one scanner only, so
    # both are tracked only if every tick waits for both scans
    ([Scanner(0.0, -2.0), Scanner(14.0, -2.0)], [(1.0, -1.0), (13.5, -1.0)]),
])
def test_localizer_process_tracks_two_robots_from_scans_on_the_bus(
        tmp_path: Path, scanners: list[Scanner], truth: list[tuple[float, float]]) -> None:
    ns, port = unique_ns(), free_port()
    keys = Keys(ns)
    lasers = [Laser(s, seed=11, stream=j) for j, s in enumerate(scanners)]
    with hub_session(ns, port) as session:
        poses: queue.SimpleQueue[Pose] = queue.SimpleQueue()
        session.declare_subscriber(keys.pose("*"),
                                   lambda s: poses.put(decode(Pose, s.payload.to_bytes())))
        alive: list[bool] = []
        session.liveliness().declare_subscriber(
            keys.alive_localizer(), lambda s: alive.append(True), history=True)
        pub_scan = declare_publisher(session, keys.scan())
        pub_sense = [declare_publisher(session, keys.sense(i)) for i in (0, 1)]
        proc = start(["localizer", "--robots", "2", "--seed", "3", "--scanners",
                      str(len(lasers)), *member_args(ns, port)], tmp_path / "localizer.log")
        try:
            wait_for(lambda: bool(alive), 30, "the localizer's liveliness token")
            step = 0.04  # both drive +y at 0.4 m/s, 10 Hz
            errors = []
            for k in range(30):
                t = 0.1 * k
                centres = [(x, y + step * k) for x, y in truth]
                if k == 3:
                    pub_scan.put(b"\x92\x01 not a scan")
                if k == 5 and len(lasers) > 1:  # a scanner of a row the team has not
                    pub_scan.put(encode(Scan(t, k, lasers[0].scan(centres), 0.0, -2.0,
                                             math.pi / 2, scanner=2, scanners=3)))
                for j in reversed(range(len(lasers))):  # in any order
                    s = lasers[j].scanner
                    pub_scan.put(encode(Scan(t, k, lasers[j].scan(centres), s.x, s.y, s.theta,
                                             scanner=j, scanners=len(lasers))))
                for i in (0, 1):
                    pub_sense[i].put(encode(Sense(t, k, i, False, False, step if k else 0.0,
                                                  0.0, 0.0, 6.0, 0.1)))
                got = {}
                while len(got) < 2:  # lockstep: the poses of tick k before tick k+1
                    pose = poses.get(timeout=20)
                    assert pose.k == k and pose.source == "pf"
                    got[pose.robot] = pose
                errors.append([math.dist((got[i].x, got[i].y), centres[i]) for i in (0, 1)])
                if k >= 15:  # moving straight ahead: the heading is known by now
                    for i in (0, 1):
                        assert abs(got[i].theta - math.pi / 2) < 0.2
        finally:
            end(proc)
        out = proc.stdout.read().decode() if proc.stdout else ""
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["scans"] == 30 and summary["dropped"] == len(scanners)
    assert max(max(e) for e in errors) < 0.05
    assert np.mean(errors) < 0.02


def test_team_with_pf_recovers_a_kidnapped_robot(tmp_path: Path) -> None:
    """A whole simulated team (recorder, 3 agents, localizer, world) with the filter:
    robot 0 is carried 1 m into the ice at t = 25 s (its phase, which depends on x
    alone, does not jump); the filter finds it again within 20 scans and the team
    keeps patrolling."""
    out = tmp_path / "run"
    proc = start(["sim", "--duration", "45", "--map", "no-algae", "--start", "in-phase",
                  "--kidnap", "0@25:0,1",
                  "--out", str(out), "--quiet", "--no-scene"], tmp_path / "sim.log")
    try:
        proc.wait(180)
    finally:
        end(proc)
        end_children_of_run(out)
    assert proc.returncode == 0, (tmp_path / "sim.log").read_text()[-3000:]
    world = json.loads((out / "logs" / "world.out").read_text().strip().splitlines()[-1])
    assert world["ticks"] == 450 and world["timeouts"] == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["localization"] == "pf" and summary["loc_error_mean_m"] < 0.03

    run = load_run(out)
    loc = localization_errors(run)
    kidnap_k = 250
    err0 = loc.pf[0]
    assert err0[kidnap_k] > 0.5  # the kidnapping happened and the filter did not know
    recovered = next(k for k in range(kidnap_k, err0.size) if (err0[k:] < 0.05).all())
    assert recovered - kidnap_k <= 20
    for robot in (1, 2):
        assert loc.pf[robot][5:].max() < 0.05
    # odometry never hears of the kidnapping: its error stays about 1 m
    assert loc.odometry[0][-1] > 0.8
    # the team did not fall apart: every agent answered every tick (no timeouts above),
    # and the carried robot crossed the edge again after it was put down
    tr = run.truth[0]
    after = tr.y[tr.t > 26.0]
    assert (np.diff(np.sign(after)) != 0).any()
    for robot in (0, 1, 2):
        assert run.states[robot].t[-1] >= 44.8
