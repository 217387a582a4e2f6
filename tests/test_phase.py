"""Phase wrap, eq. 3.1 both ways, the desired-phase update (eq. 4.5-4.8) and the speed
along the patrol."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.phase import (
    arc_may_begin,
    boundary_phase_shift,
    consensus_term,
    desired_phase_step,
    leg_speed,
    limit_lead,
    phase_to_position,
    position_to_phase,
    wrap_2pi,
    wrap_pi,
)

angles = st.floats(-100.0, 100.0, allow_nan=False)


@given(angles)
def test_wrap_pi_range_and_equivalence(a):
    w = wrap_pi(a)
    assert -math.pi < w <= math.pi
    assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-9)
    assert math.isclose(math.sin(w), math.sin(a), abs_tol=1e-9)


@given(angles)
def test_wrap_2pi_range(a):
    w = wrap_2pi(a)
    assert 0.0 <= w < 2 * math.pi
    assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-9)


def test_wrap_pi_edges():
    assert wrap_pi(math.pi) == pytest.approx(math.pi)
    assert wrap_pi(-math.pi) == pytest.approx(math.pi)
    assert wrap_pi(3 * math.pi / 2) == pytest.approx(-math.pi / 2)


def test_eq_3_1_forward_and_back():
    lo, hi = 1.0, 3.0
    assert position_to_phase(1.0, lo, hi, +1) == pytest.approx(0.0)
    assert position_to_phase(2.0, lo, hi, +1) == pytest.approx(math.pi / 2)
    assert position_to_phase(3.0, lo, hi, +1) == pytest.approx(math.pi)
    # coming back the phase runs pi -> 2 pi (the thesis's case condition is the direction)
    assert position_to_phase(3.0, lo, hi, -1) == pytest.approx(math.pi)
    assert position_to_phase(2.0, lo, hi, -1) == pytest.approx(3 * math.pi / 2)
    assert position_to_phase(1.0 + 1e-12, lo, hi, -1) == pytest.approx(2 * math.pi, abs=1e-9)
    # outside the segment clips to its ends
    assert position_to_phase(5.0, lo, hi, +1) == pytest.approx(math.pi)


@given(st.floats(0.0, 2 * math.pi - 1e-9), st.floats(-5, 5), st.floats(0.1, 10))
def test_eq_3_1_inverse_round_trip(phase, lo, length):
    hi = lo + length
    s, direction = phase_to_position(phase, lo, hi)
    assert lo - 1e-9 <= s <= hi + 1e-9
    back = position_to_phase(s, lo, hi, direction)
    assert abs(wrap_pi(back - phase)) < 1e-7


def test_empty_segment_refused():
    with pytest.raises(ValueError):
        position_to_phase(1.0, 2.0, 2.0, 1)


def test_boundary_shift_eq_4_8():
    # robot at s = 2 going up; segment [1, 3] -> [1, 5]: phase pi/2 -> pi/4
    assert boundary_phase_shift(2.0, 1, (1.0, 3.0), (1.0, 5.0)) == pytest.approx(-math.pi / 4)
    assert boundary_phase_shift(2.0, 1, (1.0, 3.0), (1.0, 3.0)) == 0.0


def test_feedback_linearisation_cancels_boundary_shift():
    a = desired_phase_step(1.0, 0.05, 0.1, shift=0.3, consensus=0.0)
    b = desired_phase_step(1.0, 0.05, 0.1, shift=0.0, consensus=0.0)
    assert a == pytest.approx(b) == pytest.approx(1.005)


def test_consensus_pulls_towards_neighbours_and_ends_are_one_sided():
    # a lagging middle robot is pulled forward by both neighbours
    assert consensus_term(1.0, 1.2, 1.2, 0.3) == pytest.approx(0.3 * 0.2 + 0.3 * 0.2)
    assert consensus_term(1.0, None, 1.2, 0.3) == pytest.approx(0.06)
    assert consensus_term(1.0, 0.8, None, 0.3) == pytest.approx(-0.06)
    # across the 2 pi seam the shorter way round is taken
    assert consensus_term(0.05, None, 2 * math.pi - 0.05, 0.5) == pytest.approx(-0.05)


def test_an_arc_begins_when_the_desired_phase_is_a_lead_short_of_its_middle():
    step = (1.0, 1.2)  # the arc takes the phase from 1.0 to 1.2: its middle is 1.1
    assert not arc_may_begin(1.09, *step)
    assert arc_may_begin(1.1, *step) and arc_may_begin(1.5, *step)
    # half the arc's duration early, so its middle falls on the team's
    assert not arc_may_begin(1.04, *step, lead=0.05)
    assert arc_may_begin(1.05, *step, lead=0.05)
    # across the 2 pi seam (a step from 6.2 to 0.1, middle 6.2 + 0.0916)
    seam = (6.2, 0.1)
    assert not arc_may_begin(6.25, *seam) and arc_may_begin(0.01, *seam)


@given(st.floats(0.0, 2 * math.pi - 1e-9), st.floats(0.01, 0.5), st.floats(-3.0, 3.0),
       st.floats(0.0, 0.2))
def test_arc_may_begin_exactly_past_the_middle_less_the_lead(level, step, offset, lead):
    go = arc_may_begin(wrap_2pi(level + offset), level, wrap_2pi(level + step), lead)
    assert go == (wrap_pi(offset - (0.5 * step - lead)) >= 0.0)


def test_a_leg_is_paced_to_end_when_its_arc_is_due():
    v_max, slow, floor = 0.5, 0.1, 0.025
    # 1 m to go at speed in 4 s: 0.25 m/s
    assert leg_speed(4.0, 1.0, 0.0, False, v_max, slow, floor) == pytest.approx(0.25)
    # 0.2 m of it to measure at 0.1 m/s takes 2 s: the rest in the 2 s left
    assert leg_speed(4.0, 0.8, 0.2, False, v_max, slow, floor) == pytest.approx(0.4)
    # late, or out of time: as fast as it may, and never above the measuring speed there
    assert leg_speed(-1.0, 1.0, 0.0, False, v_max, slow, floor) == v_max
    assert leg_speed(1.0, 1.0, 0.5, False, v_max, slow, floor) == v_max
    assert leg_speed(4.0, 1.0, 0.0, True, v_max, slow, floor) == slow
    # far too early: the floor, not a stop (the arc waits instead)
    assert leg_speed(1000.0, 0.1, 0.0, False, v_max, slow, floor) == floor


def test_time_to_spare_goes_to_measuring_down_to_the_fine_speed():
    v_max, slow, floor, fine = 0.5, 0.1, 0.025, 0.025
    # 20 s for 1 m fast and 0.2 m to measure: the measuring at the fine speed (8 s),
    # the fast metre in the 12 s left
    assert leg_speed(20.0, 1.0, 0.2, True, v_max, slow, floor, fine) == pytest.approx(fine)
    assert leg_speed(20.0, 1.0, 0.2, False, v_max, slow, floor, fine) == pytest.approx(1 / 12)
    # 6 s: 2 s for the fast part at 0.8 v_max, the 4 s left to measure the 0.2 m in
    assert leg_speed(6.0, 0.8, 0.2, True, v_max, slow, floor, fine) == pytest.approx(0.05)
    assert leg_speed(6.0, 0.8, 0.2, False, v_max, slow, floor, fine) == pytest.approx(0.4)
    # no time to spare: the measuring speed, as without it
    assert leg_speed(4.0, 0.8, 0.2, False, v_max, slow, floor, fine) == pytest.approx(0.4)
    assert leg_speed(4.0, 0.8, 0.2, True, v_max, slow, floor, fine) == slow
    # nothing to measure left: the fine speed changes nothing
    assert leg_speed(4.0, 1.0, 0.0, False, v_max, slow, floor, fine) == pytest.approx(0.25)


@given(st.floats(0, 100), st.floats(0, 10), st.floats(0.001, 10))
def test_measuring_finely_never_makes_a_leg_that_had_time_late(left, fast, slow_m):
    v_max, slow, floor, fine = 0.5, 0.1, 0.025, 0.025
    v_fast = leg_speed(left, fast, slow_m, False, v_max, slow, floor, fine)
    v_slow = leg_speed(left, fast, slow_m, True, v_max, slow, floor, fine)
    assert fine <= v_slow <= slow and floor <= v_fast <= v_max
    if left >= fast / (0.8 * v_max) + slow_m / slow:  # on time at the measuring speed
        assert fast / v_fast + slow_m / v_slow <= left * (1 + 1e-9) + 1e-9


@given(st.floats(-100, 100), st.floats(0, 10), st.floats(0, 10), st.booleans())
def test_leg_speed_stays_within_the_robot_and_the_measuring_limits(left, fast, slow_m, measuring):
    v = leg_speed(left, fast, slow_m, measuring, 0.5, 0.1, 0.025)
    assert 0.025 <= v <= 0.5
    if measuring:
        assert v <= 0.1


def test_limit_lead():
    assert limit_lead(2.5, 1.0, 1.0) == pytest.approx(2.0)
    assert limit_lead(0.2, 1.0, 1.0) == pytest.approx(0.2)
    assert limit_lead(1.5, 1.0, 1.0) == pytest.approx(1.5)


@given(st.lists(st.floats(-50.0, 50.0), min_size=1, max_size=20))
def test_the_array_wrappers_are_the_scalar_ones_element_by_element(angles):
    """One convention everywhere: the report's and the localizer's wrapping over arrays
    gives what the agents' gives one angle at a time, (-pi, pi] and [0, 2 pi)."""
    from agent.phase import wrap_2pi, wrap_2pi_array, wrap_pi_array

    assert wrap_pi_array(angles) == pytest.approx([wrap_pi(a) for a in angles], abs=1e-12)
    assert wrap_2pi_array(angles) == pytest.approx([wrap_2pi(a) for a in angles], abs=1e-12)
    assert float(wrap_pi_array(-math.pi)) == wrap_pi(-math.pi) == pytest.approx(math.pi)


@given(st.floats(0.0, 1.0), st.floats(0.1, 10.0), st.sampled_from([1, -1]))
def test_eq_3_1_over_arrays_is_the_agents_eq_3_1(frac, length, direction):
    from agent.phase import position_to_phase_array

    lo = 2.0
    x = lo + frac * length
    want = position_to_phase(x, lo, lo + length, direction)
    assert float(position_to_phase_array(x, lo, lo + length, direction)) == pytest.approx(
        want, abs=1e-12)


def test_a_boundary_move_leaves_the_controllers_desired_phase_alone():
    """Issue 22, item 7: eq. 4.5 with 4.7 cancels the phase jump of eq. 4.8 in the running
    controller, not only in the function. Two robots, alike but for their upper
    neighbour's workload: one's boundary moves, the other's does not. Their position
    phases then differ by exactly the jump of eq. 4.8, and their desired phases not at
    all."""
    from agent.controller import Controller, Gains, Neighbour, RobotLimits
    from agent.patrol import PatrolConfig

    # a fixed cycle: the rate the team agrees on depends on the segments, which differ here
    gains, cfg, lim = Gains(k_phi=0.3, cycle_s=200.0), PatrolConfig(), RobotLimits()
    x, y = 1.3, -0.4  # below the ice, between passes
    robots = [Controller(0, 0.0, 2.0, 0.0, 6.0, x, gains, cfg, lim) for _ in range(2)]
    first = [c.step(0.1, x, y, math.pi / 2, False, False, None, None, False, True)
             for c in robots]
    assert first[0] == first[1]
    me = robots[0].published
    assert me is not None

    def upper(workload: float) -> Neighbour:  # in phase with us: no consensus pull
        return Neighbour(1, 2.0, 4.0, me.phase_des, workload, me.turns)

    moved = robots[0].step(0.1, x, y, math.pi / 2, False, False, None, upper(me.workload + 2.0),
                           False, True)
    still = robots[1].step(0.1, x, y, math.pi / 2, False, False, None, upper(me.workload),
                           False, True)
    assert moved.hi > still.hi + 0.1  # the busier neighbour gave up some of its segment
    jump = boundary_phase_shift(x, still.direction, (still.lo, still.hi), (moved.lo, moved.hi))
    assert abs(jump) > 0.01
    assert wrap_pi(moved.phase - still.phase) == pytest.approx(jump, abs=1e-12)
    assert moved.phase_des == pytest.approx(still.phase_des, abs=1e-12)
