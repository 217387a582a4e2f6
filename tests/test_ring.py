"""The laws on a ring of neighbours (agent.ring, agent.stability's ring bounds, the
team's agreement cut on a ring)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.partition import SegmentView, shared_boundary
from agent.phase import consensus_term, desired_phase_step, wrap_pi
from agent.ring import (
    arc_lengths,
    chain_sides,
    frame_shift,
    initial_arc,
    ring_bins,
    ring_neighbours,
    ring_shared_boundary,
    ring_update,
)
from agent.stability import (
    check_gains,
    phase_gain_bound,
    ring_laplacian,
    ring_phase_gain_bound,
    ring_workload_gain_bound,
    ring_workload_matrix,
)
from agent.team import chain_max, team_max


def test_neighbours_wrap_round_the_live_ring() -> None:
    assert ring_neighbours(0, range(5)) == (4, 1)
    assert ring_neighbours(4, range(5)) == (3, 0)
    assert ring_neighbours(2, [0, 2, 7]) == (0, 7)
    assert ring_neighbours(7, [0, 2, 7]) == (2, 0)
    assert ring_neighbours(1, [1, 3]) == (3, 3)  # a ring of two: one neighbour, both sides
    with pytest.raises(ValueError):
        ring_neighbours(1, [1])


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 12), st.floats(2.0, 40.0), st.data())
def test_the_arcs_tile_the_ring_with_no_gap_or_overlap(n: int, length: float, data) -> None:
    """From any arcs at least the minimum long and any workloads, a step of eq. 4.3
    leaves arcs that still tile the ring (they add up to L, each starts where the one
    below it ends) and none shorter than the minimum."""
    min_len = 0.1
    cuts = data.draw(st.lists(st.floats(0.01, 1.0), min_size=n, max_size=n))
    spare = length - n * min_len
    arcs = [min_len + c * spare / sum(cuts) for c in cuts]
    start = data.draw(st.floats(-length, length))
    b = [start + sum(arcs[:i]) for i in range(n)]
    work = data.draw(st.lists(st.floats(0.0, 50.0), min_size=n, max_size=n))
    k_s = data.draw(st.floats(0.001, 0.2))
    new = ring_update(b, work, length, k_s, min_len)
    lengths = arc_lengths(new, length)
    assert sum(lengths) == pytest.approx(length, abs=1e-9)
    assert min(lengths) >= min_len - 1e-9
    # each boundary moved at most half the slack of either arc beside it
    for i in range(n):
        assert abs(new[i] - b[i]) <= 0.5 * max(arcs[i - 1], arcs[i]) + 1e-9


@settings(max_examples=10, deadline=None)
@given(st.integers(3, 10), st.lists(st.floats(0.3, 1.5), min_size=10, max_size=10))
def test_the_workload_law_balances_a_ring(n: int, depths: list[float]) -> None:
    d = depths[:n]
    length = 3.0 * n
    b = [length * i / n for i in range(n)]
    k_s = 0.9 * ring_workload_gain_bound(d)
    for _ in range(1500):
        work = [di * a for di, a in zip(d, arc_lengths(b, length), strict=True)]
        b = ring_update(b, work, length, k_s, 0.05)
    work = [di * a for di, a in zip(d, arc_lengths(b, length), strict=True)]
    mean = sum(work) / n
    assert max(work) - min(work) < 1e-6 * mean
    # equal work means arcs inversely proportional to the depths
    inverse = [1 / di for di in d]
    for arc, w in zip(arc_lengths(b, length), inverse, strict=True):
        assert arc == pytest.approx(length * w / sum(inverse), rel=1e-5)


def test_the_ring_workload_matrix_is_the_law_linearised() -> None:
    """The error map of ``ring_update`` near balance is I - K_s M (M of
    ``ring_workload_matrix``), found by moving each boundary a little."""
    d = [0.4, 1.2, 0.7, 0.3, 0.9]
    n, length, k_s = len(d), 20.0, 0.05
    inverse = [1 / x for x in d]
    arcs = [length * w / sum(inverse) for w in inverse]
    base = [sum(arcs[:i]) for i in range(n)]

    def errors(b: list[float]) -> np.ndarray:
        work = np.array(d) * np.array(arc_lengths(b, length))
        return np.roll(work, -1) - work  # e_i = Psi_{i+1} - Psi_i

    def step(b: list[float]) -> list[float]:
        work = [x * a for x, a in zip(d, arc_lengths(b, length), strict=True)]
        return ring_update(b, work, length, k_s, 0.01)

    eps = 1e-6
    rng = np.random.default_rng(3)
    for _ in range(5):
        push = list(np.array(base) + eps * rng.standard_normal(n))
        e0, e1 = errors(push), errors(step(push))
        predicted = (np.eye(n) - k_s * ring_workload_matrix(d)) @ e0
        assert np.allclose(e1, predicted, atol=1e-9 * eps + 1e-12, rtol=1e-4)
        assert abs(e0.sum()) < 1e-12  # the errors round a ring add up to nothing


@pytest.mark.parametrize("n", range(2, 13))
def test_the_phase_bound_is_the_ring_laplacian_s(n: int) -> None:
    lam = np.sort(np.linalg.eigvalsh(ring_laplacian(n)))
    expected = np.sort([2 - 2 * math.cos(2 * math.pi * k / n) for k in range(n)])
    assert np.allclose(lam, expected)  # a ring of two: the pair twice, 0 and 4
    assert ring_phase_gain_bound(n) == pytest.approx(2 / lam.max())
    assert ring_phase_gain_bound(n) <= phase_gain_bound(n) + 1e-12  # a ring is no easier
    if n == 3:
        assert ring_phase_gain_bound(3) == pytest.approx(2 / 3)
    if n % 2 == 0 and n > 2:
        assert ring_phase_gain_bound(n) == pytest.approx(0.5)


def test_check_gains_refuses_a_phase_gain_the_ring_cannot_take() -> None:
    assert check_gains(4, 0.55, 0.1, 2.0) == []  # a chain of 4 takes 0.586
    problems = check_gains(4, 0.55, 0.1, 2.0, closed=True)
    assert len(problems) == 1 and "ring of 4" in problems[0] and "0.5000" in problems[0]
    assert check_gains(8, 0.3, 0.1, 2.0, closed=True) == []
    assert check_gains(5, 0.3, 0.3, 2.0, closed=True)  # K_s over 2 / (4 d_max)


def _ring_phases(n: int, k_phi: float, ticks: int, seed: int) -> float:
    """Largest |phase error| round a ring after ``ticks`` of eq. 4.7 on both
    neighbours, from small random offsets."""
    rng = np.random.default_rng(seed)
    phases = list(0.01 * rng.standard_normal(n))
    for _ in range(ticks):
        phases = [
            desired_phase_step(phases[i], 0.0, 0.1, 0.0, consensus_term(
                phases[i], phases[(i - 1) % n], phases[(i + 1) % n], k_phi))
            for i in range(n)
        ]
    return max(abs(wrap_pi(phases[(i + 1) % n] - phases[i])) for i in range(n))


@settings(max_examples=10, deadline=None)
@given(st.integers(2, 10), st.integers(0, 1000))
def test_the_phase_law_on_a_ring_is_stable_below_the_bound_and_not_above(
        n: int, seed: int) -> None:
    bound = ring_phase_gain_bound(n)
    assert _ring_phases(n, 0.95 * bound, 400, seed) < 1e-6
    assert _ring_phases(n, 1.05 * bound, 400, seed) > 0.05  # the fastest mode grows


def test_the_boundary_of_two_neighbours_in_frames_a_turn_apart_is_one_value() -> None:
    length = 12.0
    lower = SegmentView(8.0, 12.3, 2.0)  # robot n-1, its arc over s = L
    upper = SegmentView(0.25, 4.0, 2.6)  # robot 0, in its frame from 0
    assert frame_shift(upper.lo, lower.hi, length) == length
    b = ring_shared_boundary(lower, upper, length, 0.1, 0.15)
    # the lower keeps b, the upper b - L: one boundary, from the same published values
    assert b == shared_boundary(lower, SegmentView(12.25, 16.0, 2.6), 0.1, 0.15)
    assert b == pytest.approx(12.275 + 0.1 * 0.6)
    # in one frame, the chain's rule bit for bit
    a, c = SegmentView(1.0, 3.0, 1.0), SegmentView(3.01, 5.0, 1.5)
    assert ring_shared_boundary(a, c, length, 0.1, 0.15) == shared_boundary(a, c, 0.1, 0.15)


def test_initial_arcs_and_bins() -> None:
    assert initial_arc(0, 4, 10.0) == (0.0, 2.5)
    assert initial_arc(3, 4, 10.0) == (7.5, 10.0)
    b = ring_bins(10.04, 0.1)
    assert round(10.04 / b) * b == pytest.approx(10.04) and abs(b - 0.1) < 0.001


@settings(max_examples=30, deadline=None)
@given(st.integers(3, 12), st.data())
def test_the_team_s_maxima_on_a_cut_ring_reach_everyone_and_are_forgotten(n: int, data
                                                                          ) -> None:
    """Chain maxima over the ring cut between its highest id and its lowest: within
    n ticks every robot knows the team's largest need, and once that need is gone it
    is forgotten within n ticks; fed round the uncut ring it would never be."""
    needs = data.draw(st.lists(st.floats(1.0, 100.0), min_size=n, max_size=n))

    def run(needs: list[float], state: list[tuple[float, float]], cut: bool, ticks: int
            ) -> list[tuple[float, float]]:
        for _ in range(ticks):
            new = []
            for i in range(n):
                lo, up = (i - 1) % n, (i + 1) % n
                use_lo, use_up = chain_sides(i, lo, up) if cut else (True, True)
                m = chain_max(needs[i], state[lo][0] if use_lo else None,
                              state[up][1] if use_up else None)
                new.append((m.below, m.above))
            state = new
        return state

    def seen(state: list[tuple[float, float]], i: int, cut: bool) -> float:
        lo, up = (i - 1) % n, (i + 1) % n
        use_lo, use_up = chain_sides(i, lo, up) if cut else (True, True)
        return team_max(needs[i], state[lo][0] if use_lo else None,
                        state[up][1] if use_up else None)

    start = [(0.0, 0.0)] * n
    state = run(needs, start, True, n)
    assert all(seen(state, i, True) == max(needs) for i in range(n))
    top = needs.index(max(needs))
    old = max(needs)
    needs[top] = 0.5  # its segment got easy
    later = run(needs, state, True, n)
    assert all(seen(later, i, True) == max(needs) for i in range(n))
    uncut = run(needs, run(needs[:top] + [old] + needs[top + 1:], start, False, n), False,
                3 * n)
    assert max(seen(uncut, i, False) for i in range(n)) == old  # never forgotten


def test_robots_spread_evenly_round_the_phase_circle_stay_spread() -> None:
    """The ring's twisted states (README, "Phase on a ring"): five robots 2 pi / 5
    apart are an equilibrium of eq. 4.7 with wrapped errors, and a small push does not
    bring them to agreement. The DESIGN's starts (winding 0) never meet one; it is
    documented, not handled."""
    n, k_phi = 5, 0.3
    phases = [2 * math.pi * i / n + 0.01 * math.sin(i) for i in range(n)]
    for _ in range(500):
        phases = [
            desired_phase_step(phases[i], 0.0, 0.1, 0.0, consensus_term(
                phases[i], phases[(i - 1) % n], phases[(i + 1) % n], k_phi))
            for i in range(n)
        ]
    errors = [wrap_pi(phases[(i + 1) % n] - phases[i]) for i in range(n)]
    assert all(e == pytest.approx(2 * math.pi / n, abs=1e-6) for e in errors)
