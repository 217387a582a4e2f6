"""Phase wrap, eq. 3.1 both ways, the desired-phase update (eq. 4.5-4.8) and the speed
along the patrol."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent.phase import (
    boundary_phase_shift,
    consensus_term,
    desired_phase_step,
    limit_lead,
    pass_speed,
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


def test_pass_speed_runs_legs_and_steps_each_arc_at_the_middle_of_its_step():
    v_max, slow = 0.5, 0.1
    step = (1.0, 1.2)  # the arc takes the phase from 1.0 to 1.2: its middle is 1.1
    # on a leg: full speed whether behind or a little ahead, slowly where it measures
    for phase_des in (0.95, 1.0, 1.3):
        assert pass_speed(phase_des, 1.0, *step, True, False, False, v_max, slow) == v_max
        assert pass_speed(phase_des, 1.0, *step, True, True, False, v_max, slow) == slow
    # far ahead of the desired phase (more than max_ahead): wait on the leg
    assert pass_speed(0.4, 1.0, *step, True, False, False, v_max, slow) == 0.0
    # at an arc: wait until the desired phase reaches the middle of the step...
    assert pass_speed(1.09, 1.0, *step, False, False, False, v_max, slow) == 0.0
    assert pass_speed(1.1, 1.0, *step, False, False, False, v_max, slow) == v_max
    assert pass_speed(1.5, 1.0, *step, False, False, False, v_max, slow) == v_max
    # ...and once begun, drive it through
    assert pass_speed(1.0, 1.05, *step, False, False, True, v_max, slow) == v_max
    # across the 2 pi seam (a step from 6.2 to 0.1, middle 6.2 + 0.0916)
    seam = (6.2, 0.1)
    assert pass_speed(6.25, 6.2, *seam, False, False, False, v_max, slow) == 0.0
    assert pass_speed(0.01, 6.2, *seam, False, False, False, v_max, slow) == v_max
    assert pass_speed(6.0, 0.05, *seam, True, False, False, v_max, slow) == v_max


@given(st.floats(0.0, 2 * math.pi - 1e-9), st.floats(0.01, 0.5), st.floats(-3.0, 3.0))
def test_pass_speed_is_zero_or_a_speed_of_the_robot(level, step, lead):
    v = pass_speed(wrap_2pi(level + lead), level, level, wrap_2pi(level + step), False,
                   False, False, 0.5, 0.1)
    assert v in (0.0, 0.5)
    assert (v == 0.5) == (wrap_pi(lead - 0.5 * step) >= 0.0)


def test_limit_lead():
    assert limit_lead(2.5, 1.0, 1.0) == pytest.approx(2.0)
    assert limit_lead(0.2, 1.0, 1.0) == pytest.approx(0.2)
    assert limit_lead(1.5, 1.0, 1.0) == pytest.approx(1.5)
