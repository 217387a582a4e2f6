"""The patrol on a closed edge (agent.ringcontrol): the chain's controller in the
edge's frame on a ring, run with the world core round a floe."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent.controller import Neighbour
from agent.patrol import Motion
from agent.phase import wrap_pi
from agent.ring import initial_arc
from agent.ringcontrol import RingController
from simworld.floes import floe_map
from simworld.maps import GridMap
from simworld.world import World

DT = 0.1


@pytest.fixture(scope="module")
def floe() -> GridMap:
    return floe_map("floe:1,shape=round,size=2.5,algae=blooms")


def test_a_ring_gain_outside_the_ring_s_bound_is_refused(floe: GridMap) -> None:
    from agent.controller import Gains

    edge = floe.closed_edge
    with pytest.raises(ValueError, match="ring of 4"):
        RingController(0, 4, edge, *initial_arc(0, 4, edge.length), *edge.at(0.1, -1.0),
                       Gains(k_phi=0.55))  # a chain of 4 would take it (bound 0.586)


def test_the_pose_in_the_edge_frame_is_the_robot_s_own_turn(floe: GridMap) -> None:
    edge = floe.closed_edge
    length = edge.length
    # robot 2 of 3 holds [2L/3, L]; a point just past s = 0 is, in its frame, past L
    ctl = RingController(2, 3, edge, *initial_arc(2, 3, length), *edge.at(length - 0.2, -1))
    s, d, psi = ctl.edge_pose(*edge.at(0.05, 0.4), edge.tangent_angle(0.05) + math.pi / 2)
    assert s == pytest.approx(length + 0.05, abs=1e-6)
    assert d == pytest.approx(0.4, abs=1e-6)
    assert psi == pytest.approx(math.pi / 2, abs=1e-6)


def _run_ring(gmap: GridMap, n: int, seconds: float
              ) -> tuple[list[RingController], list[dict[str, np.ndarray]]]:
    edge = gmap.closed_edge
    world = World(gmap, n, "in-phase", seed=1)
    ctls = [RingController(i, n, edge, *initial_arc(i, n, edge.length), *world.truth(i)[:2])
            for i in range(n)]
    published: list[Neighbour | None] = [None] * n
    log: list[dict[str, np.ndarray]] = []
    for _ in range(int(seconds / DT)):
        cmds, now, row = {}, [], {"lo": np.zeros(n), "hi": np.zeros(n), "psi": np.zeros(n),
                                  "d": np.zeros(n), "leg": np.zeros(n, bool),
                                  "heading_err": np.zeros(n)}
        for i, ctl in enumerate(ctls):
            x, y, th = world.truth(i)
            r = world.sense(i)
            out = ctl.step(DT, x, y, th, r.ice, r.algae, published[(i - 1) % n],
                           published[(i + 1) % n])
            cmds[i] = (out.v, out.omega)
            now.append(ctl.published)
            s, d, psi = ctl.edge_coordinates
            row["lo"][i], row["hi"][i], row["psi"][i], row["d"][i] = out.lo, out.hi, psi, d
            row["leg"][i] = out.motion in (Motion.UNDER, Motion.EXIT)
            # the heading from the local normal, in the world
            normal = edge.tangent_angle(s) + math.pi / 2
            row["heading_err"][i] = abs(wrap_pi(2 * (th - normal)) / 2)
        published = now
        log.append(row)
        world.step(cmds, DT)
    return ctls, log


def test_a_ring_of_three_patrols_a_floe_along_its_normals_and_tiles_it(floe: GridMap
                                                                        ) -> None:
    n = 3
    edge = floe.closed_edge
    ctls, log = _run_ring(floe, n, 150.0)
    for row in log[1:]:
        # the arcs tile the ring: each starts where the one below ends, a whole turn
        # apart at most, and together they are the ring
        for i in range(n):
            j = (i + 1) % n
            gap = row["lo"][j] - row["hi"][i]
            assert abs(gap - round(gap / edge.length) * edge.length) < 1e-9
        assert (row["hi"] - row["lo"]).sum() == pytest.approx(edge.length, abs=1e-9)
    legs = np.array([r["heading_err"][r["leg"]].max(initial=0.0) for r in log[300:]])
    # once going, the legs in and out run along the local normal (a leg's first ticks
    # may be a few tenths off it, out of its arc)
    assert np.median(legs) < 0.02 and legs.max() < 0.5
    depth = np.array([r["d"] for r in log])
    assert depth.min() > -1.05  # never further out than the start line
    assert depth.max() < 1.0  # nor deeper than the deepest algae (0.57 m) and its margins
    assert depth[300:].max() > 0.5  # but the legs do go in under the bloom
    # every robot has measured its arc and says so
    assert all(c.published is not None and c.published.workload > 0 for c in ctls)
