"""Pure parts of surviving faults: fault specs and chaos schedules, the segment a
joining robot claims, coverage of the edge and neighbour pairs under changing
membership."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.partition import SegmentView, join_segment, shared_boundary
from deploy.faults import Fault, FaultSpecError, chaos_schedule, check_schedule, due, parse_fault
from report.faults import coverage_ok, segment_union
from report.series import active_pairs


def test_fault_specs_parse_and_freeze_brings_its_thaw():
    assert parse_fault("kill:1@120") == [Fault(120.0, "kill", 1)]
    assert parse_fault("freeze:2@200-230") == [Fault(200.0, "freeze", 2),
                                                Fault(230.0, "thaw", 2)]
    assert parse_fault("join:3@400.5") == [Fault(400.5, "join", 3)]
    for bad in ("kill:1", "boom:1@3", "freeze:1@30-20", "kill:1@3-4", "kill:x@3"):
        with pytest.raises(FaultSpecError):
            parse_fault(bad)


def test_schedule_is_refused_when_it_cannot_happen_and_counts_bodies():
    ok = parse_fault("kill:1@100") + parse_fault("restart:1@200") + parse_fault("join:3@50")
    assert check_schedule(ok, team=3) == 4
    with pytest.raises(FaultSpecError, match="still running"):
        check_schedule(parse_fault("restart:1@10"), team=3)
    with pytest.raises(FaultSpecError, match="not running"):
        check_schedule(parse_fault("kill:1@10") + parse_fault("kill:1@20"), team=3)
    with pytest.raises(FaultSpecError, match="no agent 5"):
        check_schedule(parse_fault("kill:5@10"), team=3)
    with pytest.raises(FaultSpecError, match="already in the team"):
        check_schedule(parse_fault("join:2@10"), team=3)


@given(st.integers(0, 10_000), st.integers(3, 8), st.floats(300, 5000))
def test_chaos_schedules_are_reproducible_and_carry_out(seed, team, duration):
    schedule = chaos_schedule(seed, team, duration)
    assert schedule == chaos_schedule(seed, team, duration)
    check_schedule(schedule, team)  # every step possible: raises otherwise
    down: set[int] = set()
    for f in schedule:  # at least two agents up at any time, all back before the end
        (down.add if f.kind in ("kill", "freeze") else down.discard)(f.agent)
        assert team - len(down) >= 2
        assert f.at_s <= 0.8 * duration
    assert not down


def test_due_faults_follow_the_clock():
    schedule = sorted(parse_fault("kill:1@10") + parse_fault("freeze:2@20-30"))
    assert due(schedule, 0, 9.9) == []
    assert due(schedule, 0, 25.0) == schedule[:2]
    assert due(schedule, 2, 31.0) == schedule[2:]


def test_joining_robot_takes_a_quarter_of_each_neighbour_and_they_agree():
    lower, upper = SegmentView(0.0, 3.0, 1.5), SegmentView(3.0, 6.0, 1.5)
    lo, hi = join_segment(lower, upper, 0.0, 6.0)
    assert (lo, hi) == (1.5, 4.5)
    me = SegmentView(lo, hi, 0.0)
    # next tick both sides of each shared boundary compute it from the same values
    assert shared_boundary(lower, me, 0.0, 0.3) == pytest.approx(2.25)
    assert shared_boundary(me, upper, 0.0, 0.3) == pytest.approx(3.75)
    assert join_segment(None, upper, 0.0, 6.0) == (0.0, 4.5)  # a new lowest id
    assert join_segment(lower, None, 0.0, 6.0) == (1.5, 6.0)
    assert join_segment(None, None, 0.0, 6.0) == (0.0, 6.0)


def test_joining_robot_never_claims_past_a_live_neighbour_it_has_not_heard():
    lower, upper = SegmentView(0.0, 3.0, 1.5), SegmentView(3.0, 6.0, 1.5)
    # robot 0 alive but unheard: the half of robot 2's segment next to it, not [0, 4.5]
    assert join_segment(None, upper, 0.0, 6.0, lower_unheard=True) == (3.0, 4.5)
    assert join_segment(lower, None, 0.0, 6.0, upper_unheard=True) == (1.5, 3.0)
    # a heard neighbour on that side, or a real end of the chain, as before
    assert join_segment(lower, upper, 0.0, 6.0, lower_unheard=True) == (1.5, 4.5)
    assert join_segment(None, upper, 0.0, 6.0) == (0.0, 4.5)
    # the heard one claims to the end past the unheard one (the bus may say so): the claim
    # still stops short of the end
    assert join_segment(None, SegmentView(0.0, 3.0, 1.5), 0.0, 6.0,
                        lower_unheard=True) == pytest.approx((0.75, 1.5))
    assert join_segment(SegmentView(3.0, 6.0, 1.5), None, 0.0, 6.0,
                        upper_unheard=True) == pytest.approx((4.5, 5.25))


def test_a_join_between_neighbours_claiming_the_same_stretch_is_never_empty():
    # both neighbours' segments have the same middle (as no two live robots should, but
    # the bus may say so): the middle half of that stretch, and a controller can start on
    # it; never to an end of the edge past a live neighbour
    same = SegmentView(0.0, 3.1, 0.6)
    assert join_segment(same, same, 0.0, 6.0) == pytest.approx((0.775, 2.325))
    assert join_segment(SegmentView(1.0, 2.0, 0.6), SegmentView(0.5, 2.5, 0.6),
                        0.0, 6.0) == pytest.approx((1.25, 2.0))


def test_segment_union_measures_gap_and_overlap():
    lo, hi = np.array([0.0, 2.0, 4.5]), np.array([2.0, 4.0, 6.0])
    assert segment_union(lo, hi, 0.0, 6.0) == pytest.approx((0.5, 0.0))
    lo, hi = np.array([0.0, 1.5, np.nan]), np.array([2.0, 6.0, np.nan])
    assert segment_union(lo, hi, 0.0, 6.0) == pytest.approx((0.0, 0.5))
    assert list(coverage_ok(np.array([0.0, 0.1, np.nan]), np.array([0.0, 0.0, 0.0]))) == [
        True, False, False]


def test_pairs_follow_membership():
    live = np.array([[1, 1, 1, 1], [1, 0, 0, 1], [1, 1, 1, 1], [0, 0, 1, 1]], dtype=bool)
    pairs, active = active_pairs([0, 1, 2, 3], live)
    assert pairs == [(0, 1), (0, 2), (1, 2), (2, 3)]
    assert active.tolist() == [
        [True, False, False, True],  # 0-1 while 1 lives
        [False, True, True, False],  # 0-2 while 1 is gone
        [True, False, False, True],
        [False, False, True, True],  # 2-3 once 3 joined
    ]
