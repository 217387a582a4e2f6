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
    from agent.phase import wrap_2pi_array

    w = float(wrap_2pi_array(a))
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


def test_sweep_rate_counts_progress_along_the_edge_not_a_legs_wobble() -> None:
    """A robot sweeping 0 -> 2 -> 0 m every 8 s (0.5 m/s along the edge) whose x
    wobbles by 10 cm at 1.5 Hz about its path: the wobble goes nowhere, so with the
    robot's directions the rate is the sweep's; without them the sum of |dx| counts the
    wobble too."""
    t = np.arange(0.0, 80.0, 0.1)
    phase = (t % 8.0) / 8.0
    x = np.where(phase < 0.5, 4.0 * phase, 4.0 * (1.0 - phase))
    direction = np.where(phase < 0.5, 1.0, -1.0)
    wobbly = x + 0.1 * np.sin(2 * np.pi * 1.5 * t + 0.3)
    with_sweeps = m.sweep_rate([(t, wobbly)], 40.0, 79.9, [(t, direction)])
    assert with_sweeps == pytest.approx(0.5, rel=0.02)
    assert m.sweep_rate([(t, wobbly)], 40.0, 79.9) > 1.3 * with_sweeps


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


# the local edge, idleness, the partition optimum, standing still, team_measures --------
def sine_edge(bins: int = 60, bin_m: float = 0.1, depth: float = 0.3) -> m.EdgeModel:
    """A curved edge over [0, 6]: y = 0.4 + 0.3 sin(2 pi x / 3), always above y = 0."""
    centres = (np.arange(bins) + 0.5) * bin_m
    return m.EdgeModel(0.0, bins * bin_m, bin_m, [depth] * bins,
                       list(0.4 + 0.3 * np.sin(2 * PI * centres / 3.0)))


def test_edge_model_local_edge_and_workload() -> None:
    straight = m.EdgeModel(0.0, 0.3, 0.1, [1.0, 2.0, 3.0])
    assert np.array_equal(straight.local_edge([-1.0, 0.1, 0.35]), [0.0, 0.0, 0.0])
    assert straight.length == pytest.approx(0.3)
    assert straight.total_workload == pytest.approx(0.6)
    assert straight.workload(0.05, 0.15) == pytest.approx(0.15)
    curved = m.EdgeModel(0.0, 0.3, 0.1, [1.0, 2.0, 3.0], [0.0, 0.2, -0.2])
    # linear between the bins' centres (0.05, 0.15, 0.25), the end values beyond them
    assert curved.local_edge([0.05, 0.1, 0.15, 0.2, 0.25]) == pytest.approx(
        [0.0, 0.1, 0.2, 0.0, -0.2])
    assert curved.local_edge([-5.0, 0.0, 0.3, 9.0]) == pytest.approx([0.0, 0.0, -0.2, -0.2])
    assert np.isnan(curved.local_edge(np.nan))
    # a last bin cut short by the edge's end has its centre in what is left of it
    short = m.EdgeModel(0.0, 0.25, 0.1, [1.0, 1.0, 1.0], [0.0, 0.1, 0.3])
    assert short.bin_centres(3) == pytest.approx([0.05, 0.15, 0.225])
    # no depth profile (a recording with no world): no true workload
    assert np.isnan(m.EdgeModel(0.0, 1.0, 0.1, ()).total_workload)


def test_crossings_of_a_curved_edge_at_every_leg() -> None:
    # a robot driving along the edge at 0.15 m/s, weaving 0.1 m about a local edge that
    # lies 0.1 m to 0.7 m above y = 0: it crosses the edge on every leg of its weave,
    # twice per 2 s period, but never the line y = 0
    edge = sine_edge()
    t = np.arange(0.0, 30.0 + 1e-9, 0.1)
    x = 0.1 + 0.15 * t
    y = 0.4 + 0.3 * np.sin(2 * PI * x / 3.0) + 0.1 * np.sin(PI * t + 0.3)
    tc, xc = m.crossings(t, x, y, edge)
    legs = np.arange(1, 31) - 0.3 / PI  # where pi t + 0.3 is a multiple of pi
    assert tc.size == 30
    assert tc == pytest.approx(legs, abs=0.02)
    assert xc == pytest.approx(0.1 + 0.15 * legs, abs=0.003)
    assert m.crossings(t, x, y)[0].size == 0  # the old rule, y = 0: never
    # a straight edge model is the old rule, to the bit
    y0 = 0.1 * np.sin(PI * t + 0.3)
    old, new = m.crossings(t, x, y0), m.crossings(t, x, y0, m.EdgeModel(0.0, 6.0, 0.1, ()))
    assert np.array_equal(old[0], new[0]) and np.array_equal(old[1], new[1])
    # samples without a position are skipped, not crossed
    y_gap = y.copy()
    y_gap[50:55] = np.nan
    assert m.crossings(t, x, y_gap, edge)[0].size == 29


def test_sweep_index_counts_reversals() -> None:
    t = np.arange(8.0)
    direction = np.array([1, 1, -1, -1, np.nan, 1, 1, -1])
    at = np.array([-1.0, 0.5, 2.0, 4.5, 5.0, 7.5])
    assert list(m.sweep_index(t, direction, at)) == [0, 0, 1, 1, 2, 3]
    assert list(m.sweep_index(np.empty(0), np.empty(0), at)) == [0] * 6


def test_idleness_on_a_schedule_by_hand() -> None:
    # point 0.5 visited at 0, 4 and 10 s; point 1.5 at 0, 5 and 10 s; point 2.5 at 3 s
    visit_t = np.array([0.0, 4.0, 10.0, 0.0, 5.0, 10.0, 3.0])
    visit_x = np.array([0.5, 0.5, 0.5, 1.5, 1.5, 1.5, 2.5])
    gaps = m.point_gaps(np.array([0.5, 1.5]), visit_t, visit_x, 0.17, 0.0, 10.0)
    # intervals 4, 6, 5, 5: mean 5, standard deviation sqrt(2 / 4), worst 6
    mean, std, worst = m.idleness(gaps, 0.0, 10.0)
    assert (mean, worst) == (5.0, 6.0)
    assert std == pytest.approx(math.sqrt(0.5))
    # a point seen once counts the whole window as its worst, and nothing in the mean
    gaps = m.point_gaps(np.array([0.5, 1.5, 2.5]), visit_t, visit_x, 0.17, 0.0, 10.0)
    assert m.idleness(gaps, 0.0, 10.0) == pytest.approx((5.0, math.sqrt(0.5), 10.0))
    out = m.idleness_measures(gaps, 0.0, 10.0, team_sweep_rate=0.5, edge_length=3.0)
    assert out["revisit_ideal_s"] == pytest.approx(6.0)  # L / (n v)
    assert out["revisit_optimum_s"] == pytest.approx(12.0)  # 2 L / (n v)
    assert out["revisit_worst_ratio"] == pytest.approx(10.0 / 12.0)
    assert math.isnan(m.idleness([], 0.0, 10.0)[1])


def test_partition_optimum() -> None:
    assert m.partition_optimum(6.0, 0.75) == pytest.approx(16.0)
    assert m.partition_optimum(6.0, 0.75, closed=True) == pytest.approx(8.0)
    assert math.isnan(m.partition_optimum(6.0, 0.0))


def lawnmower_team(
    n: int = 3, edge: m.EdgeModel | None = None, v: float = 0.25, duration_s: float = 400.0,
    dt: float = 0.1,
) -> dict[str, np.ndarray]:
    """n robots in phase, each sweeping its equal share of the edge back and forth at
    along-edge speed v, weaving 0.1 m about the local edge every 0.5 s."""
    edge = edge or sine_edge()
    t = np.arange(0.0, duration_s + dt / 2, dt)
    seg = edge.length / n
    lo = edge.edge_lo + seg * np.arange(n)[:, None] + 0.0 * t
    hi = lo + seg
    frac = np.abs(((v * t / seg) % 2.0) - 1.0)  # 1 at lo at t = 0, then towards hi
    frac = 1.0 - frac
    x = lo + seg * frac
    direction = np.where(((v * t / seg) % 2.0) < 1.0, 1.0, -1.0) + 0.0 * lo
    y = edge.local_edge(x) + 0.1 * np.sin(2 * PI * t / 0.5 + 0.2)
    phase = m.position_phase(x, lo, hi, direction)
    return dict(t=t, x=x, y=y, lo=lo, hi=hi, direction=direction, seen_phase=phase,
                seen_workload=edge.workload(lo, hi))


def test_partitioned_patrol_is_near_the_optimum() -> None:
    team = lawnmower_team()
    out = m.team_measures(**team, edge=sine_edge())
    # n v = 3 x 0.25 m/s: every point revisited within 2 L / (n v) = 16 s, at the ends
    # of each share; the robot's radius makes the worst a little shorter
    assert out["revisit_optimum_s"] == pytest.approx(16.0, rel=0.01)
    assert out["revisit_ideal_s"] == pytest.approx(8.0, rel=0.01)
    assert out["revisit_worst_ratio"] == pytest.approx(1.0, abs=0.06)
    assert out["revisit_worst_ratio"] <= 1.0 + 1e-9
    assert out["revisit_mean_s"] == pytest.approx(8.0, rel=0.1)
    assert out["revisit_std_s"] > 0
    assert out["phase_sse_rad"] == pytest.approx(0.0, abs=1e-9)
    assert out["workload_sse_m2"] == pytest.approx(0.0, abs=1e-12)
    assert out["workload_mean_m2"] == pytest.approx(0.6)  # 6 m x 0.3 m / 3
    assert out["workload_rel_sse"] == pytest.approx(0.0, abs=1e-12)
    assert out["still_frac_max"] == 0.0
    assert out["phase_converge_s"] == 0.0 and out["workload_rel_converge_s"] == 0.0


def test_team_measures_with_and_without_the_edge_shape() -> None:
    curved = sine_edge()
    team = lawnmower_team(edge=curved)
    with_shape = m.team_measures(**team, edge=curved)
    # the same motion along a straight edge at y = 0: the same visits, the same numbers
    flat = {**team, "y": team["y"] - curved.local_edge(team["x"])}
    straight = m.EdgeModel(0.0, 6.0, 0.1, curved.patrol_depth)
    along_straight = m.team_measures(**flat, edge=straight)
    path_keys = ("phase_path_sse_rad", "phase_path_max_rad")  # paths are longer curved
    assert set(with_shape) == set(along_straight)
    for key, value in with_shape.items():
        if key not in path_keys:
            assert value == pytest.approx(along_straight[key], abs=1e-9, nan_ok=True), key
    # taken for straight, the curved run is never seen to cross the edge
    blind = m.team_measures(**team, edge=straight)
    assert math.isnan(blind["revisit_mean_s"])
    assert blind["revisit_worst_s"] == pytest.approx(400.0)  # unvisited since the start


def test_team_measures_keys_and_relative_workload() -> None:
    # half the edge 1.5 m deep, half 0.3 m: 5.4 m^2 in all, 1.8 m^2 a robot for three
    depth = [1.5] * 30 + [0.3] * 30
    edge = m.EdgeModel(0.0, 6.0, 0.1, depth)
    team = lawnmower_team(edge=edge)
    out = m.team_measures(**team, edge=edge)
    expected = {
        "phase_sse_rad", "phase_max_rad", "phase_path_sse_rad", "phase_path_max_rad",
        "workload_sse_m2", "workload_max_m2", "workload_rel_sse", "workload_rel_max",
        "phase_sse_agents_rad", "workload_sse_agents_m2", "workload_mean_m2",
        "revisit_mean_s", "revisit_std_s", "revisit_worst_s", "revisit_ideal_s",
        "revisit_optimum_s", "revisit_worst_ratio", "still_frac_max", "phase_converge_s",
        "workload_converge_s", "workload_rel_converge_s",
    }
    assert expected <= set(out) and all(isinstance(v, float) for v in out.values())
    # equal shares: workloads 3.0, 1.8 and 0.6 m^2, both pairs 1.2 m^2 apart
    assert out["workload_mean_m2"] == pytest.approx(1.8)
    assert out["workload_sse_m2"] == pytest.approx(1.2)
    assert out["workload_rel_sse"] == pytest.approx(1.2 / 1.8)
    assert out["workload_rel_max"] == pytest.approx(1.2 / 1.8)
    assert math.isnan(out["workload_converge_s"]) and math.isnan(out["workload_rel_converge_s"])
    # the agents believed their shares were balanced
    believed = {**team, "seen_workload": np.full_like(team["x"], 1.8)}
    assert m.team_measures(**believed, edge=edge)["workload_sse_agents_m2"] == 0.0
    # shares balanced at 1.2 and 2.4 m: every robot 1.8 m^2
    lo = np.array([0.0, 1.2, 2.4])[:, None] + 0.0 * team["t"]
    hi = np.array([1.2, 2.4, 6.0])[:, None] + 0.0 * team["t"]
    balanced = m.team_measures(**{**team, "lo": lo, "hi": hi}, edge=edge)
    assert balanced["workload_sse_m2"] == pytest.approx(0.0, abs=1e-12)
    assert balanced["workload_rel_sse"] == pytest.approx(0.0, abs=1e-12)


def test_team_measures_with_a_robot_gone() -> None:
    # robot 2 leaves for the last half: robots 0 and 1 are the only pair there, and the
    # mean workload per robot is the edge's over two
    edge = m.EdgeModel(0.0, 6.0, 0.1, [1.5] * 30 + [0.3] * 30)
    team = lawnmower_team(edge=edge)
    live = np.ones(team["x"].shape, dtype=bool)
    live[2, team["t"] > 200.0] = False
    out = m.team_measures(**team, edge=edge, live=live)
    assert out["workload_mean_m2"] == pytest.approx(2.7)
    assert out["workload_sse_m2"] == pytest.approx(1.2)  # pair 0-1 only: 1.8 - 3.0
    assert out["workload_rel_sse"] == pytest.approx(1.2 / 2.7)
    # the edge robot 2 no longer patrols is never visited in the second half: it waits
    # from robot 2's last visit, shortly before the window, to the end
    assert 200.0 < out["revisit_worst_s"] < 215.0


def test_still_fraction() -> None:
    t = np.arange(0.0, 100.0 + 1e-9, 0.1)
    # moving at 0.1 m/s until 90 s, then stopped: 100 of the last quarter's 250 steps
    x = 0.1 * np.minimum(t, 90.0)
    y = np.zeros_like(t)
    assert m.still_fraction(t, x, y, 75.0) == pytest.approx(0.4)
    # creeping at 5 mm/s (0.5 mm a tick) counts as standing still; 2 cm/s does not
    assert m.still_fraction(t, 0.005 * t, y, 75.0) == 1.0
    assert m.still_fraction(t, 0.02 * t, y, 75.0) == 0.0
    # steps while the robot is out of the team do not count
    live = t < 90.0
    assert m.still_fraction(t, x, y, 75.0, live) == 0.0
    assert math.isnan(m.still_fraction(t, x, y, 200.0))
    # in a team, the robot that stood still longest: robot 1 stops at 350 s of 400 s
    edge = m.EdgeModel(0.0, 6.0, 0.1, [0.3] * 60)
    team = lawnmower_team(edge=edge)
    stop = team["t"] >= 350.0
    for name in ("x", "y"):
        team[name][1, stop] = team[name][1, stop][0]
    out = m.team_measures(**team, edge=edge)
    assert out["still_frac_max"] == pytest.approx(0.5, abs=0.01)  # 50 of the last 100 s


def test_worst_idleness_counts_the_visits_before_the_window() -> None:
    """A point at a segment's end is seen once per cycle (480 s): a window of 700 s
    sees it once, and its worst wait is the cycle, not the window."""
    visits = np.array([100.0, 580.0, 1060.0])
    assert m.worst_idleness(visits, 700.0, 1400.0, 0.0) == pytest.approx(480.0)
    assert m.worst_idleness(visits, 1100.0, 1600.0, 0.0) == pytest.approx(540.0)  # open end
    assert m.worst_idleness(np.array([100.0]), 700.0, 1400.0, 0.0) == pytest.approx(1300.0)
    assert m.worst_idleness(np.empty(0), 700.0, 1400.0, 0.0) == pytest.approx(1400.0)
    assert m.worst_idleness(np.array([900.0]), 700.0, 1400.0, 0.0) == pytest.approx(900.0)
