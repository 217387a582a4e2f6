"""Partition invariants of the boundary update (eq. 4.1-4.3) under random workloads."""

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.partition import SegmentView, chain_update, shared_boundary

MIN_LEN = 0.2


@st.composite
def chains(draw):
    n = draw(st.integers(2, 12))
    edge = draw(st.floats(n * MIN_LEN + 0.1, 50.0))
    cuts = sorted(draw(st.lists(st.floats(0.0, 1.0), min_size=n - 1, max_size=n - 1)))
    # spread the cuts so every segment starts at least MIN_LEN long
    span = edge - n * MIN_LEN
    bounds = [0.0] + [c * span + (i + 1) * MIN_LEN for i, c in enumerate(cuts)] + [edge]
    workloads = draw(st.lists(st.floats(0.0, 20.0), min_size=n, max_size=n))
    k_s = draw(st.floats(0.001, 0.5))
    return bounds, workloads, k_s


@settings(max_examples=300)
@given(chains(), st.integers(1, 30))
def test_partition_invariants(chain, steps):
    bounds, workloads, k_s = chain
    s = bounds
    for _ in range(steps):
        s = chain_update(s, workloads, k_s, MIN_LEN)
        assert s[0] == bounds[0] and s[-1] == bounds[-1]  # ends fixed
        lengths = [b - a for a, b in zip(s, s[1:], strict=False)]
        assert all(length >= MIN_LEN - 1e-9 for length in lengths)  # ordered, no overlap
        # no gap: consecutive segments share their boundary, and they tile the edge
        assert sum(lengths) == pytest.approx(bounds[-1] - bounds[0])


def test_boundary_moves_towards_the_busier_robot():
    lower = SegmentView(0.0, 2.0, 3.0)
    upper = SegmentView(2.0, 4.0, 1.0)
    b = shared_boundary(lower, upper, 0.1, MIN_LEN)
    assert b == pytest.approx(2.0 - 0.2)  # lower is busier: its segment shrinks


def test_both_neighbours_compute_the_same_boundary():
    lower = SegmentView(0.0, 2.0, 3.0)
    upper = SegmentView(2.0, 4.0, 1.0)
    assert shared_boundary(lower, upper, 0.05, MIN_LEN) == shared_boundary(
        SegmentView(*[lower.lo, lower.hi, lower.workload]), upper, 0.05, MIN_LEN
    )


def test_gap_left_by_a_lost_robot_is_split():
    lower = SegmentView(0.0, 2.0, 1.0)
    upper = SegmentView(4.0, 6.0, 1.0)  # the robot that owned [2, 4] is gone
    assert shared_boundary(lower, upper, 0.1, MIN_LEN) == pytest.approx(3.0)


def test_balanced_workloads_converge():
    # depths 1.5 on [0, 3), 0.3 beyond: true workloads from the boundaries
    def psi(a, b):
        deep = max(0.0, min(b, 3.0) - a)
        return 1.5 * deep + 0.3 * (b - a - deep)

    s = [0.0, 2.0, 4.0, 6.0]
    for _ in range(2000):
        w = [psi(a, b) for a, b in zip(s, s[1:], strict=False)]
        s = chain_update(s, w, 0.05, MIN_LEN)
    w = [psi(a, b) for a, b in zip(s, s[1:], strict=False)]
    assert max(w) - min(w) < 1e-6
    assert s[1] == pytest.approx(1.2) and s[2] == pytest.approx(2.4)
