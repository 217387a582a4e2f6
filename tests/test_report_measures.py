"""Pure measure functions of report.measures on synthetic arrays."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from report import measures as m

PI = math.pi
finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


def test_position_phase_towards_hi() -> None:
    x = np.array([1.0, 1.5, 2.0, 3.0])
    phi = m.position_phase(x, 1.0, 3.0, 1)
    assert phi == pytest.approx([0.0, PI / 4, PI / 2, PI])


def test_position_phase_towards_lo() -> None:
    x = np.array([3.0, 2.5, 2.0, 1.0 + 1e-9])
    phi = m.position_phase(x, 1.0, 3.0, -1)
    assert phi == pytest.approx([PI, 5 * PI / 4, 3 * PI / 2, 2 * PI], abs=1e-6)
    # exactly at lo going down is a full cycle: wrapped to 0
    assert m.position_phase(1.0, 1.0, 3.0, -1) == pytest.approx(0.0)


def test_position_phase_clips_outside_segment() -> None:
    assert m.position_phase(0.0, 1.0, 3.0, 1) == pytest.approx(0.0)
    assert m.position_phase(5.0, 1.0, 3.0, 1) == pytest.approx(PI)
    assert m.position_phase(5.0, 1.0, 3.0, -1) == pytest.approx(PI)


def test_position_phase_arrays_mixed_directions() -> None:
    phi = m.position_phase([2.0, 2.0], [1.0, 1.0], [3.0, 3.0], [1, -1])
    assert phi == pytest.approx([PI / 2, 3 * PI / 2])


@given(finite)
def test_wrap_pi_range_and_equivalence(a: float) -> None:
    w = float(m.wrap_pi(a))
    assert -PI < w <= PI
    assert math.isclose(math.remainder(w - a, 2 * PI), 0.0, abs_tol=1e-9)


@given(finite)
def test_wrap_2pi_range(a: float) -> None:
    w = float(m.wrap_2pi(a))
    assert 0.0 <= w < 2 * PI


def test_wrap_pi_edges() -> None:
    assert m.wrap_pi(PI) == pytest.approx(PI)
    assert m.wrap_pi(-PI) == pytest.approx(PI)
    assert m.wrap_pi(1.5 * PI) == pytest.approx(-0.5 * PI)


def test_pair_errors_wrap_across_zero() -> None:
    values = {0: np.array([6.2]), 1: np.array([0.1]), 2: np.array([0.3])}
    e = m.pair_errors(values, m.neighbour_pairs([2, 0, 1]), wrap=True)
    assert e[:, 0] == pytest.approx([0.1 - 6.2 + 2 * PI, 0.2])


def test_true_workload_hand_values() -> None:
    depth = [1.0, 2.0, 3.0]  # bins of 1 m from x = 0
    assert m.true_workload(0.0, 3.0, 0.0, 1.0, depth) == pytest.approx(6.0)
    assert m.true_workload(0.5, 2.5, 0.0, 1.0, depth) == pytest.approx(0.5 + 2.0 + 1.5)
    assert m.true_workload(1.25, 1.75, 0.0, 1.0, depth) == pytest.approx(1.0)
    lo = np.array([0.0, 1.0])
    hi = np.array([1.0, 3.0])
    assert m.true_workload(lo, hi, 0.0, 1.0, depth) == pytest.approx([1.0, 5.0])


@given(st.floats(0, 6), st.floats(0, 6), st.floats(0, 6))
def test_true_workload_is_additive(a: float, b: float, c: float) -> None:
    a, b, c = sorted((a, b, c))
    depth = list(np.linspace(0.3, 1.5, 60))
    whole = m.true_workload(a, c, 0.0, 0.1, depth)
    parts = m.true_workload(a, b, 0.0, 0.1, depth) + m.true_workload(b, c, 0.0, 0.1, depth)
    assert whole == pytest.approx(parts, abs=1e-9)


def test_hold_and_staleness() -> None:
    out = m.hold(
        np.array([1.0, 2.0]),
        np.array([10.0, 20.0]),
        np.array([0.5, 1.0, 1.5, 2.0, 9.0]),
        max_age=5.0,
    )
    assert np.isnan(out[0]) and np.isnan(out[4])
    assert list(out[1:4]) == [10.0, 10.0, 20.0]


def test_steady_state_of_decaying_error() -> None:
    t = np.linspace(0.0, 100.0, 1001)
    e = np.vstack([2.0 * np.exp(-t / 10.0), -np.exp(-t / 10.0)])
    mean, top = m.steady_state(t, e)
    last = t >= 75.0
    expected = (2.0 * np.exp(-t[last] / 10).mean() + np.exp(-t[last] / 10).mean()) / 2
    assert mean == pytest.approx(expected)
    assert top == pytest.approx(2.0 * math.exp(-7.5))
    q1, _ = m.window_abs(t, e, 0.0, 0.25)
    assert q1 > mean


def test_steady_state_ignores_missing_samples() -> None:
    t = np.arange(8.0)
    e = np.array([[np.nan] * 6 + [0.1, 0.3]])
    assert m.steady_state(t, e) == pytest.approx((0.2, 0.3))


def test_converge_time() -> None:
    t = np.arange(0.0, 60.0, 0.01)
    e = np.vstack([np.exp(-t / 5.0), 0.5 * np.exp(-t / 5.0)])
    expected = 5.0 * math.log(1 / 0.15)
    assert m.converge_time(t, e, 0.15) == pytest.approx(expected, abs=0.02)
    spiked = e.copy()
    spiked[1, t.searchsorted(30.0)] = 0.2  # leaves the band once more at 30 s
    assert m.converge_time(t, spiked, 0.15) == pytest.approx(30.01, abs=1e-6)
    assert math.isnan(m.converge_time(t, e + 0.2, 0.15))
    assert m.converge_time(t, e * 0.0, 0.15) == 0.0


def test_recovery_time_is_the_first_return_after_leaving_the_band() -> None:
    t = np.arange(0.0, 100.0, 0.1)
    # in band, pushed out at 10 s, decays back, then a later excursion at 60-70 s
    e = np.where(t < 10.0, 0.01, 0.5 * np.exp(-(t - 10.0) / 5.0))
    e = np.where((t >= 60.0) & (t < 70.0), 0.1, e)
    expected = 10.0 + 5.0 * math.log(0.5 / 0.05)
    assert m.recovery_time(t, e[None, :], 0.05) == pytest.approx(expected, abs=0.11)
    assert math.isnan(m.converge_time(t[t < 65.0], e[None, t < 65.0], 0.05))
    assert m.recovery_time(t, np.full((2, t.size), 0.01), 0.05) == 0.0
    assert math.isnan(m.recovery_time(t, np.where(t < 10.0, 0.01, 1.0)[None, :], 0.05))


def test_path_length_phase_cycles() -> None:
    # back and forth along x over [0, 1] at 0.1 m per sample: 20 samples per cycle
    x = np.concatenate(
        [
            np.linspace(1, 0, 11)[:-1],
            np.tile(np.concatenate([np.linspace(0, 1, 11)[:-1], np.linspace(1, 0, 11)[:-1]]), 3),
        ]
    )
    y = np.zeros_like(x)
    direction = np.where(np.diff(x, append=x[-1] - 0.1) > 0, 1, -1)
    phase = m.path_length_phase(x, y, direction)
    assert np.isnan(phase[:10]).all()  # before the first reversal at lo
    first = phase[10:30]
    assert first == pytest.approx(2 * PI * np.arange(20) / 20)
    assert np.nanmax(phase) < 2 * PI
    assert np.isfinite(phase[10:]).all()


def test_path_length_phase_needs_a_cycle_length() -> None:
    x = np.linspace(0, 1, 10)
    phase = m.path_length_phase(x, np.zeros(10), np.r_[-1, -1, np.ones(8)])
    assert np.isnan(phase).all()


def test_crossings_interpolated() -> None:
    t = np.array([0.0, 1.0, 2.0, 3.0])
    x = np.array([0.0, 1.0, 2.0, 3.0])
    y = np.array([-1.0, 1.0, 3.0, -1.0])
    tc, xc = m.crossings(t, x, y)
    assert tc == pytest.approx([0.5, 2.75])
    assert xc == pytest.approx([0.5, 2.75])


def test_revisit_hand_values() -> None:
    visit_t = np.array([0.0, 0.5, 10.0, 20.0, 5.0])
    visit_x = np.array([0.5, 0.55, 0.45, 0.5, 0.9])
    mean, worst = m.revisit_intervals(np.array([0.5]), visit_t, visit_x, 0.17, 0.0, 20.0)
    assert (mean, worst) == (10.0, 10.0)
    # a point seen only once in the window counts the whole window as its worst
    mean, worst = m.revisit_intervals(np.array([0.5, 0.9]), visit_t, visit_x, 0.17, 0.0, 20.0)
    assert (mean, worst) == (10.0, 20.0)


def test_revisit_on_a_synthetic_sweep() -> None:
    # one robot sweeping x back and forth over [0, 2] at 0.5 m/s while weaving across
    # y = 0 every 0.1 s: every point is visited on each pass
    t = np.arange(0.0, 80.0, 0.01)
    x = 2.0 * np.abs(((t / 4.0) % 2.0) - 1.0)  # period 8 s, 0.5 m/s
    y = np.sin(2 * PI * t / 0.2 + 0.1)
    tc, xc = m.crossings(t, x, y)
    points = m.edge_points(0.0, 2.0)
    assert len(points) == 21
    # an inner point at s is passed at 8k + 4 - 2s and 8k + 4 + 2s: intervals 4 s +- 4(1 - s)
    inner = points[(points >= 0.5) & (points <= 1.5)]
    mean, worst = m.revisit_intervals(inner, tc, xc, 0.17, 40.0, 80.0)
    assert mean == pytest.approx(4.0, rel=0.05)
    assert worst == pytest.approx(6.0, abs=0.2)
    # near the ends both passes fall within 1 s and count as one visit: every 8 s
    mean_all, worst_all = m.revisit_intervals(points, tc, xc, 0.17, 40.0, 80.0)
    assert mean_all > mean
    assert worst_all == pytest.approx(8.0, abs=0.2)
    rate = m.sweep_rate([(t, x)], 40.0, 80.0)
    assert rate == pytest.approx(0.5, rel=0.01)
    assert m.ideal_revisit(2.0, rate) == pytest.approx(4.0, rel=0.01)


def test_speedup() -> None:
    t = np.arange(0.0, 10.01, 0.1)
    log_ns = (t * 1e9 / 50.0).astype(np.int64) + 123
    assert m.speedup(t, log_ns) == pytest.approx(50.0, rel=1e-6)
    assert math.isnan(m.speedup(t[:1], log_ns[:1]))


def test_running_mean_and_smoothed_convergence_ignore_a_sawtooth():
    import numpy as np

    from report import measures as m

    t = np.arange(0.0, 200.0, 0.1)
    # a decaying error plus a 5 s saw-tooth of amplitude 0.2 that never goes away
    saw = 0.2 * ((t % 5.0) / 5.0)
    e = np.exp(-t / 10.0) + saw
    assert np.isnan(m.converge_time(t, e[None, :], 0.15))  # raw: the teeth leave the band
    settled = m.converge_time(t, e[None, :], 0.15, smooth_s=10.0)
    assert 20.0 < settled < 40.0  # smoothed: the mean tooth (0.1) is inside the band
    assert np.allclose(m.running_mean(t, np.ones_like(t), 10.0), 1.0)
