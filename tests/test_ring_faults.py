"""Faults round a ring, the pure cores (issue 18, item 3): a robot's neighbours close the
ring over the arc of one that left and a joiner claims its share (agent.ring,
agent.membership, agent.ringcontrol); the report's coverage round the ring
(report.ring). tests/test_ring_faults_process.py plays a kill and a restart on the bus."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from agent.membership import Decision, Membership
from agent.partition import SegmentView
from agent.ring import initial_arc, ring_join_arc, ring_shared_boundary
from agent.ringcontrol import RingController
from report.ring import live_ring_workload_errors, ring_coverage, ring_union
from simworld.floes import floe_map

K_S, MIN = 0.1, 0.15


def test_a_joiner_claims_from_the_middle_of_one_neighbour_s_arc_to_the_other_s() -> None:
    assert ring_join_arc(SegmentView(0.0, 4.0, 1.0), SegmentView(4.0, 8.0, 1.0),
                         12.0) == (2.0, 6.0)
    # over s = 0: the upper neighbour's frame is a turn below the lower one's
    assert ring_join_arc(SegmentView(8.0, 12.0, 1.0), SegmentView(0.0, 4.0, 1.0),
                         12.0) == (10.0, 14.0)
    # a neighbour not heard yet is live: the claim stops at the heard one's end there
    assert ring_join_arc(SegmentView(0.0, 4.0, 1.0), None, 12.0) == (2.0, 4.0)
    assert ring_join_arc(None, SegmentView(4.0, 8.0, 1.0), 12.0) == (4.0, 6.0)
    # the only other robot, on both sides: the upper third of its arc
    assert ring_join_arc(SegmentView(3.0, 15.0, 1.0), SegmentView(3.0, 15.0, 1.0), 12.0,
                         same=True) == (11.0, 15.0)
    with pytest.raises(ValueError):
        ring_join_arc(None, None, 12.0)
    # two neighbours claiming the same arc (the bus may say so): its middle half, never
    # an empty claim
    assert ring_join_arc(SegmentView(2.0, 6.0, 1.0), SegmentView(2.0, 6.0, 1.0),
                         12.0) == (3.0, 5.0)


def _tiles(arcs: list[tuple[float, float]], length: float) -> None:
    """Each arc begins where the one below it round the ring ends (in whole turns), and
    together they are the ring."""
    for (_, hi), (lo, _) in zip(arcs, arcs[1:] + arcs[:1], strict=True):
        turns = (hi - lo) / length
        assert turns == pytest.approx(round(turns), abs=1e-9)
    assert sum(hi - lo for lo, hi in arcs) == pytest.approx(length, abs=1e-9)
    gap, overlap = ring_union(np.array([a for a, _ in arcs]), np.array([b for _, b in arcs]),
                              length)
    assert gap == pytest.approx(0.0, abs=1e-9) and overlap == pytest.approx(0.0, abs=1e-9)


def _meet(lower: SegmentView, upper: SegmentView, length: float) -> tuple[float, float]:
    """The boundary two ring neighbours agree on, in each one's frame: the lower's hi and
    the upper's lo, as agent.ringcontrol computes them on both sides."""
    b = ring_shared_boundary(lower, upper, length, K_S, MIN)
    shift = round((lower.hi - upper.lo) / length) * length
    return b, b - shift


@settings(max_examples=60, deadline=None)
@given(st.integers(3, 9), st.floats(4.0, 40.0), st.data())
def test_a_robot_leaves_and_comes_back_and_the_arcs_tile_the_ring_each_time(
        n: int, length: float, data) -> None:
    """Robot k leaves: k-1 and k+1 meet in the middle of its arc, and the n-1 arcs tile
    the ring; it comes back and claims from the middle of one neighbour's arc to the
    middle of the other's, each meets it halfway, and the n arcs tile it again. Any
    arcs, any frames (each robot's a whole number of turns off), any workloads; the arc
    that leaves under half the ring (the neighbours tell its turns by the gap)."""
    cuts = data.draw(st.lists(st.floats(0.05, 1.0), min_size=n, max_size=n))
    spare = length - n * MIN
    sizes = [MIN + c * spare / sum(cuts) for c in cuts]
    k = data.draw(st.integers(0, n - 1))
    assume(sizes[k] < 0.45 * length)
    start = data.draw(st.floats(-length, length))
    turns = data.draw(st.lists(st.integers(-2, 2), min_size=n, max_size=n))
    work = data.draw(st.lists(st.floats(0.0, 5.0), min_size=n, max_size=n))
    arcs = [SegmentView(start + sum(sizes[:i]) + turns[i] * length,
                        start + sum(sizes[:i + 1]) + turns[i] * length, work[i])
            for i in range(n)]
    below, above = (k - 1) % n, (k + 1) % n
    # the gap closed over: both neighbours compute their one new boundary
    hi, lo = _meet(arcs[below], arcs[above], length)
    left = list(arcs)
    left[below] = SegmentView(arcs[below].lo, hi, arcs[below].workload)
    left[above] = SegmentView(lo, arcs[above].hi, arcs[above].workload)
    del left[k]
    _tiles([(a.lo, a.hi) for a in left], length)
    # robot k comes back between them
    a, b = left[(k - 1) % (n - 1)], left[k % (n - 1)]
    claim = ring_join_arc(a, b, length)
    assert claim[0] < claim[1] <= claim[0] + length
    joiner = SegmentView(*claim, 0.0)
    a_hi, j_lo = _meet(a, joiner, length)
    j_hi, b_lo = _meet(joiner, b, length)
    back = list(left)
    back[(k - 1) % (n - 1)] = SegmentView(a.lo, a_hi, a.workload)
    back[k % (n - 1)] = SegmentView(b_lo, b.hi, b.workload)
    back.insert(k, SegmentView(j_lo, j_hi, 0.0))
    _tiles([(s.lo, s.hi) for s in back], length)
    assert j_hi - j_lo > 0  # it has work: a quarter of each neighbour's arc, about


def test_a_robot_restarted_in_a_running_ring_claims_a_share_of_its_neighbours() -> None:
    m: Membership[SegmentView] = Membership(1, 4, neighbour_timeout_s=0.3, ring=True)
    for rid in (0, 2, 3):
        m.alive(rid, True)
    assert m.neighbours() == (0, 2)
    assert m.decide(600, 10.0) is Decision.STAND_STILL  # neither heard yet
    m.heard(0, 600, SegmentView(15.0, 19.0, 1.0))  # robot 0's frame: a turn up
    m.heard(2, 600, SegmentView(7.0, 11.0, 1.0))
    assert m.decide(601, 10.1) is Decision.ACT
    assert m.first_segment(601, 0.0, 16.0) == (17.0, 25.0)
    # with one other robot live it is the neighbour on both sides
    two: Membership[SegmentView] = Membership(1, 4, ring=True)
    two.alive(3, True)
    assert two.neighbours() == (3, 3)
    two.heard(3, 600, SegmentView(2.0, 18.0, 1.0))
    assert two.first_segment(600, 0.0, 16.0) == pytest.approx((38 / 3, 18.0))
    alone: Membership[SegmentView] = Membership(1, 4, ring=True)
    assert alone.neighbours() == (None, None)
    assert alone.first_segment(600, 0.0, 16.0) == initial_arc(1, 4, 16.0)


def test_a_robot_alone_on_the_ring_owns_the_whole_contour_and_two_share_it() -> None:
    edge = floe_map("floe:1,shape=round,size=2.5,algae=blooms").closed_edge
    length = edge.length
    lo, hi = initial_arc(2, 4, length)
    ctl = RingController(2, 4, edge, lo, hi, *edge.at(lo + 0.3, -0.5))
    x, y = edge.at(lo + 0.3, -0.5)
    out = ctl.step(0.1, x, y, 0.0, False, False, None, None, False, False, ids=(None, None))
    assert (out.lo, out.hi) == (lo, lo + length)
    assert ctl.neighbour_ids == (None, None)
    # another comes back, the only neighbour on both sides, with its claim (the upper
    # third of the ring): the two meet it halfway at both ends and share the ring
    other = RingController(0, 4, edge, *ring_join_arc(
        SegmentView(lo, lo + length, 1.0), None, length, same=True), *edge.at(lo, -0.5))
    out = ctl.step(0.1, x, y, 0.0, False, False, None, None, ids=(0, 0))
    assert (out.lo, out.hi) == (lo, lo + length)  # not heard yet: both ends kept
    mine = ctl.published
    ox, oy = edge.at(lo, -0.5)
    first = other.step(0.1, ox, oy, 0.0, False, False, None, None, ids=(2, 2))
    claim = other.published  # the next tick, each on the other's state of this one
    theirs = other.step(0.1, ox, oy, 0.0, False, False, mine, mine, ids=(2, 2))
    again = ctl.step(0.1, x, y, 0.0, False, False, claim, claim, ids=(0, 0))
    assert (first.lo, first.hi) == pytest.approx((lo + 2 * length / 3, lo + length))
    _tiles([(again.lo, again.hi), (theirs.lo, theirs.hi)], length)
    assert 0.15 < theirs.hi - theirs.lo < 0.5 * length


def test_coverage_round_the_ring_counts_gaps_and_overlaps_across_s_zero() -> None:
    L = 10.0
    lo, hi = np.array([-1.0, 3.0, 16.0]), np.array([3.0, 6.0, 19.0])  # 6..9 in the 3rd
    assert ring_union(lo, hi, L) == pytest.approx((0.0, 0.0))
    assert ring_union(lo[:2], hi[:2], L) == pytest.approx((3.0, 0.0))
    assert ring_union(np.array([-1.0, 2.0]), np.array([5.0, 9.5]), L) == pytest.approx(
        (0.0, 3.5))
    live = np.array([[True, True], [True, False], [True, True]])
    gap, overlap = ring_coverage(np.tile(lo[:, None], 2), np.tile(hi[:, None], 2), live, L)
    assert gap == pytest.approx([0.0, 3.0]) and overlap == pytest.approx([0.0, 0.0])


def test_across_a_dead_robot_s_arc_the_neighbours_closing_in_pass_and_lies_do_not() -> None:
    """Robot 1 of 4 died: robot 0's first state naming robot 2 as its upper neighbour,
    its hi met in the middle of the gap, is plausible to robot 2 (in robot 0's frame, a
    turn up); a hi past the middle of robot 2's arc is not, gap or no gap."""
    from agent.plausible import Claim, neighbour_problem
    from tests.test_plausible import MIN_SEG, RING_L, ring_state

    n = 4
    # arcs [0, 2.5] [2.5, 5] [5, 7.5] [7.5, 10]; robot 0's frame a turn up
    r0 = ring_state(0, 9, 10.0, 12.5, 1.0, n, upper=1)
    r2 = ring_state(2, 9, 5.0, 7.5, 1.0, n, lower=1)
    mine = {9: Claim(r2.lo, r2.hi, r2.workload)}
    # robot 2's lo and robot 0's hi meet in the middle of the gap: 3.75 (13.75 to robot 0)
    closing = ring_state(0, 10, 10.0, 13.75, 1.0, n, upper=2)
    assert neighbour_problem(closing, 2, "lower", mine, r0, MIN_SEG, RING_L) is None
    for hi in (16.5, 17.0):  # past the middle of robot 2's arc, or all of it
        lie = ring_state(0, 10, 10.0, hi, 1.0, n, upper=2)
        assert neighbour_problem(lie, 2, "lower", mine, r0, MIN_SEG, RING_L) is not None


def test_the_workload_errors_are_those_of_the_live_neighbours_round_the_ring() -> None:
    from report.ring import RingEdge

    edge = RingEdge(length=10.0, bin_m=1.0, patrol_depth=[1.0] * 5 + [2.0] * 5)
    lo = np.array([[0.0, 0.0], [4.0, 4.0], [7.0, 7.0]])
    hi = np.array([[4.0, 7.0], [7.0, 7.0], [10.0, 10.0]])
    live = np.array([[True, True], [True, False], [True, True]])
    errors = live_ring_workload_errors(lo, hi, live, edge)
    # all three: workloads 4, 1 + 4 = 5, 6; pairs (0, 1), (1, 2), (2, 0)
    assert errors[:, 0] == pytest.approx([1.0, 1.0, -2.0])
    # robot 1 gone: one pair of two, robot 0 (0..7: 5 + 4 = 9) and robot 2 (6)
    assert errors[0, 1] == pytest.approx(-3.0) and np.isnan(errors[1:, 1]).all()
