"""A ring on a closed edge from the outside: ``btrack sim --engine inprocess`` on a floe
and on an island PNG, its refusals, and the ring's measures (report.ring)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from report.ring import RingEdge, ring_errors, ring_pairs, ring_visit_gaps
from simworld.floes import floe_map
from simworld.maps import write_png

FLOE = "floe:1,shape=round,size=2.5,algae=blooms"


def btrack_sim(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """``btrack sim`` as a user runs it, its own process, waited for by its pid."""
    return subprocess.run([sys.executable, "-m", "btrack", "sim", *args], text=True,
                          capture_output=True, timeout=timeout, stdin=subprocess.DEVNULL)


def test_a_ring_runs_round_a_floe_in_process(tmp_path: Path) -> None:
    out = tmp_path / "ring"
    done = btrack_sim("--engine", "inprocess", "--map", FLOE, "--robots", "3",
                      "--start", "in-phase", "--duration", "240", "--out", str(out))
    assert done.returncode == 0, done.stderr + done.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["closed"] is True and summary["localization"] == "truth"
    m = summary["measures"]
    length = floe_map(FLOE).closed_edge.length
    assert m["edge_length_m"] == pytest.approx(length)
    # the closed edge's optimum is L / (n v), half the partition's
    assert m["revisit_worst_ratio_partition"] == pytest.approx(m["revisit_worst_ratio"] / 2)
    assert m["revisit_optimum_s"] > 0 and m["revisit_worst_s"] >= m["revisit_optimum_s"]
    # already in four minutes the ring is balancing: not a proof of the goals (README)
    assert m["workload_rel_sse"] < 0.05 and m["phase_sse_rad"] < 0.3
    for name in ("map.png", "errors.png", "report.md"):
        assert (out / name).stat().st_size > 0
    assert "ring on a closed edge" in (out / "report.md").read_text()


def test_an_island_png_is_a_ring_and_the_bus_refuses_its_pf_poses(tmp_path: Path) -> None:
    gmap = floe_map("floe:2,shape=bay,size=2.5,algae=none")
    png = tmp_path / "bay.png"
    write_png(gmap, png)
    bus = btrack_sim("--map", str(png), "--scale", "0.01", "--localization", "pf",
                     "--out", str(tmp_path / "bus"))
    assert bus.returncode == 2 and "truth poses only" in bus.stderr
    odometry = btrack_sim("--map", str(png), "--scale", "0.01", "--localization",
                          "odometry", "--out", str(tmp_path / "odometry"))
    assert odometry.returncode == 2 and "truth poses only" in odometry.stderr
    pf = btrack_sim("--engine", "inprocess", "--map", str(png), "--scale", "0.01",
                    "--localization", "pf", "--out", str(tmp_path / "pf"))
    assert pf.returncode == 2 and "truth poses only" in pf.stdout + pf.stderr
    ok = btrack_sim("--engine", "inprocess", "--map", str(png), "--scale", "0.01",
                    "--robots", "4", "--duration", "60", "--quiet", "--out",
                    str(tmp_path / "ok"))
    assert ok.returncode == 0, ok.stderr + ok.stdout
    assert json.loads((tmp_path / "ok" / "summary.json").read_text())["robots"] == 4


def test_a_ring_gain_the_ring_cannot_take_is_refused(tmp_path: Path) -> None:
    done = btrack_sim("--engine", "inprocess", "--map", FLOE, "--robots", "4",
                      "--k-phi", "0.55", "--duration", "10", "--out", str(tmp_path / "k"))
    assert done.returncode == 2 and "ring of 4" in done.stdout + done.stderr


def test_ring_errors_take_the_pair_over_s_zero_and_workload_round_the_ring() -> None:
    edge = RingEdge(length=10.0, bin_m=0.5, patrol_depth=[0.5] * 10 + [1.0] * 10)
    assert edge.total_workload == pytest.approx(7.5)
    # an arc over s = 0 in either whole turn has the same workload
    assert float(edge.workload(9.0, 11.0)) == pytest.approx(1.5)
    assert float(edge.workload(-1.0, 1.0)) == pytest.approx(1.5)
    assert ring_pairs(3) == [(0, 1), (1, 2), (2, 0)] and ring_pairs(2) == [(0, 1)]
    t = np.arange(3) * 1.0
    lo = np.array([[0.0] * 3, [4.0] * 3, [7.0] * 3])
    hi = np.array([[4.0] * 3, [7.0] * 3, [10.0] * 3])
    s = 0.5 * (lo + hi)
    s[2] = 9.7  # robot 2 nearly at its arc's end, the others in their middles
    direction = np.ones_like(s)
    errors = ring_errors(t, s, np.zeros_like(s), lo, hi, direction, np.zeros_like(s),
                         np.zeros_like(s), edge)
    assert errors.pairs[-1] == (2, 0)
    # robot 0 at phase pi/2, robot 2 at 0.9 pi: e_(2,0) = pi/2 - 0.9 pi
    assert errors.phase[2, 0] == pytest.approx(math.pi / 2 - 0.9 * math.pi)
    assert errors.workload[2, 0] == pytest.approx(float(edge.workload(0, 4))
                                                  - float(edge.workload(7, 10)))


def test_a_visit_just_before_s_equals_l_counts_for_the_point_at_zero() -> None:
    edge = RingEdge(length=10.0, bin_m=0.1, patrol_depth=[0.3] * 100, robot_radius=0.17)
    t = np.arange(0.0, 100.0, 1.0)
    # one robot crossing the contour at s = 9.95 every 5 s, a sweep each, no other
    s = np.full((1, t.size), 9.95)
    d = np.where((t // 5) % 2 == 0, -0.2, 0.2)[None, :]
    direction = np.where((t // 5) % 2 == 0, 1.0, -1.0)[None, :]
    points, gaps, worst = ring_visit_gaps(t, s, d, direction, edge, 50.0, 99.0)
    assert points[0] == 0.0
    first = gaps[0]
    assert first is not None  # s = 0 is 5 cm from s = 9.95, round the ring
    assert np.allclose(first, 5.0)
    assert gaps[50] is None and worst[50] > 49  # the point at 5 m is never visited
