"""The plausibility rules for what a neighbour may claim (agent.plausible): a chain run
by the law itself is never refused, and each lie of issue 19 is."""

from __future__ import annotations

import dataclasses

from hypothesis import given, settings
from hypothesis import strategies as st

from agent.partition import chain_update
from agent.plausible import (
    MAX_AHEAD_TICKS,
    MAX_BEHIND_TICKS,
    Bounds,
    Claim,
    neighbour_problem,
    state_problem,
)
from wire.messages import AgentState

BOUNDS = Bounds(0.0, 6.0, depth_max=7.3, bin_m=0.1, max_passes=20)
K_S, MIN_SEG = 0.1, 0.15


def state(robot: int, k: int, lo: float, hi: float, depth: float = 0.5, n: int = 3,
          **kw: object) -> AgentState:
    fields: dict = dict(t=0.1 * k, k=k, robot=robot, lo=lo, hi=hi, phase=1.0, phase_des=1.0,
                        workload=depth * (hi - lo), depth_avg=depth, direction=1,
                        lower=robot - 1, upper=robot + 1 if robot + 1 < n else -1,
                        edge_lo=0.0, edge_hi=6.0, turns=10.0, end_bins=[3], end_depths=[depth])
    fields.update(kw)
    return AgentState(**fields)


def claim(s: AgentState) -> Claim:
    return Claim(s.lo, s.hi, s.workload)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 8), ticks=st.integers(2, 12), seed=st.integers(0, 10**6))
def test_a_chain_run_by_the_law_is_never_refused(n, ticks, seed):
    import random

    rng = random.Random(seed)
    bounds = [6.0 * i / n for i in range(n + 1)]
    depths = [rng.uniform(0.3, 3.0) for _ in range(n)]
    history: list[list[AgentState]] = []
    for k in range(ticks):
        states = [state(i, k, bounds[i], bounds[i + 1], depths[i], n) for i in range(n)]
        history.append(states)
        bounds = chain_update(bounds, [s.workload for s in states], K_S, MIN_SEG)
        depths = [max(0.3, d + rng.uniform(-0.05, 0.05)) for d in depths]
    for k in range(1, ticks):
        for i in range(n):
            s, before = history[k][i], history[k - 1][i]
            assert state_problem(s, BOUNDS, k) is None
            for me, side in ((i - 1, "upper"), (i + 1, "lower")):
                if 0 <= me < n:
                    mine = {k - 1: claim(history[k - 1][me])}
                    assert neighbour_problem(s, me, side, mine, before, MIN_SEG) is None


@settings(max_examples=60, deadline=None)
@given(shift=st.floats(1e-4, 2.0), up=st.booleans())
def test_a_shared_boundary_beyond_the_laws_reach_is_refused(shift, up):
    # robots 1 and 2 of three at tick 4; robot 1's state of tick 5 puts their boundary
    # further than eq. 4.3 can move it in a tick, whatever the workloads
    r1, r2 = state(1, 4, 2.0, 4.0, 1.0), state(2, 4, 4.0, 6.0, 0.5)
    low = 4.0 - 0.5 * (4.0 - 2.0 - MIN_SEG)
    high = 4.0 + 0.5 * (6.0 - 4.0 - MIN_SEG)
    hi = (high + shift) if up else (low - shift)
    if not 2.01 < hi < 5.99:
        return
    forged = state(1, 5, 2.0, hi, 1.0)
    why = neighbour_problem(forged, 2, "lower", {4: claim(r2)}, r1, MIN_SEG)
    assert why is not None and "the law can put it only in" in why
    law = chain_update([0.0, 2.0, 4.0, 6.0], [1.0, r1.workload, r2.workload], K_S, MIN_SEG)[2]
    for honest in (law, low, high, 4.0):  # the law's own, its reach, kept
        ok = state(1, 5, 2.0, honest, 1.0)
        assert neighbour_problem(ok, 2, "lower", {4: claim(r2)}, r1, MIN_SEG) is None


def test_a_boundary_from_an_older_state_of_ours_is_not_refused():
    # on the wall clock, or over a slow link, the sender acted on our state of tick 1
    r1 = state(1, 4, 2.0, 4.0, 1.0)
    mine = {1: Claim(5.0, 6.0, 0.5), 2: Claim(4.6, 6.0, 0.7), 3: Claim(4.0, 6.0, 1.0)}
    s = state(1, 5, 2.0, 5.0, 1.0)  # reachable from tick 1's [5, 6], not tick 3's
    assert neighbour_problem(s, 2, "lower", mine, r1, MIN_SEG) is None
    assert neighbour_problem(s, 2, "lower", {3: mine[3]}, r1, MIN_SEG) is not None


def test_a_claim_past_the_middle_of_our_segment_is_refused_without_history():
    mine = {9: Claim(4.0, 6.0, 1.0)}
    # issue 19: a state claiming [0, 5.9] m for a tick not heard before
    forged = state(1, 10, 0.0, 5.9, 0.5)
    assert "further into our segment" in neighbour_problem(forged, 2, "lower", mine, None,
                                                           MIN_SEG)
    # naming someone else, it may not pass our middle; naming us (a robot just joining,
    # which split an older state of ours), a quarter further
    assert neighbour_problem(state(1, 10, 2.0, 5.1, upper=7), 2, "lower", mine, None,
                             MIN_SEG) is not None
    assert neighbour_problem(state(1, 10, 2.0, 5.1), 2, "lower", mine, None,
                             MIN_SEG) is None
    # one that sees no neighbour on our side (it lost sight of us: a freeze) owns the
    # edge to its end by the law, and may claim exactly that, not a metre short of it
    alone = state(1, 10, 0.0, 6.0, upper=-1)
    assert neighbour_problem(alone, 2, "lower", mine, None, MIN_SEG) is None
    short = state(1, 10, 0.0, 5.9, upper=-1)
    assert neighbour_problem(short, 2, "lower", mine, None, MIN_SEG) is not None
    # once it sees us again it keeps that end until it hears us: refused, each of two
    # thawed robots claiming the whole edge refused the other's states for 22 ticks
    kept = state(1, 11, 0.0, 6.0, upper=2)
    assert neighbour_problem(kept, 2, "lower", mine, None, MIN_SEG) is None
    assert neighbour_problem(state(3, 10, 4.4, 6.0, lower=2), 2, "upper",
                             {9: Claim(2.0, 4.0, 1.0)}, None, MIN_SEG) is None
    assert neighbour_problem(state(3, 10, 2.4, 6.0, lower=2), 2, "upper",
                             {9: Claim(2.0, 4.0, 1.0)}, None, MIN_SEG) is not None


def test_the_tick_window():
    s = state(1, 100, 2.0, 4.0)
    assert state_problem(s, BOUNDS, 100) is None
    assert state_problem(s, BOUNDS, None) is None  # no clock of ours yet
    assert state_problem(s, BOUNDS, 100 - MAX_AHEAD_TICKS) is None
    assert "ahead of ours" in state_problem(s, BOUNDS, 99 - MAX_AHEAD_TICKS)
    assert "ahead of ours" in state_problem(dataclasses.replace(s, k=10**9), BOUNDS, 100)
    assert state_problem(s, BOUNDS, 100 + MAX_BEHIND_TICKS) is None
    assert "behind ours" in state_problem(s, BOUNDS, 101 + MAX_BEHIND_TICKS)


@given(depth=st.floats(7.3001, 1.7e307))
def test_depths_no_patrol_can_measure_are_refused(depth):
    s = state(1, 5, 2.0, 4.0, 0.5, end_depths=[depth])
    assert "deeper than any patrol" in state_problem(s, BOUNDS, 5)
    deep = state(1, 5, 2.0, 4.0, depth)
    assert "deeper than any patrol" in state_problem(deep, BOUNDS, 5)


def test_the_other_value_rules():
    s = state(1, 5, 2.0, 4.0, 0.5)
    assert state_problem(s, BOUNDS, 5) is None
    assert "not ours" in state_problem(dataclasses.replace(s, edge_hi=5.9), BOUNDS, 5)
    assert "off the edge" in state_problem(dataclasses.replace(s, end_bins=[60]), BOUNDS, 5)
    assert "mean depth times" in state_problem(dataclasses.replace(s, workload=5e306),
                                               BOUNDS, 5)
    assert "passes per sweep" in state_problem(dataclasses.replace(s, passes=21), BOUNDS, 5)
    assert state_problem(dataclasses.replace(s, passes=20), BOUNDS, 5) is None


# On a ring: each robot's arc in its own frame, which may differ from its neighbours' by
# whole turns; the law run by agent.ring.ring_update is never refused, lies are.
RING_L = 10.0
RING_BOUNDS = Bounds(0.0, RING_L, depth_max=7.3, bin_m=0.1, max_passes=20, closed=True,
                     reach_m=0.3, reach_fraction=0.5)


def ring_state(robot: int, k: int, lo: float, hi: float, depth: float, n: int,
               **kw: object) -> AgentState:
    mid = int(0.5 * (lo + hi) // 0.1)
    fields: dict = dict(lower=(robot - 1) % n, upper=(robot + 1) % n, edge_hi=RING_L,
                        closed=True, end_bins=[int(lo // 0.1), mid])
    fields.update(kw)
    return state(robot, k, lo, hi, depth, n, **fields)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(3, 8), ticks=st.integers(2, 10), seed=st.integers(0, 10**6),
       turns=st.lists(st.integers(-3, 3), min_size=8, max_size=8),
       start=st.floats(0.0, RING_L))
def test_a_ring_run_by_the_law_is_never_refused_in_any_turn(n, ticks, seed, turns, start):
    import random

    from agent.ring import arc_lengths, ring_update

    rng = random.Random(seed)
    bounds = [start + RING_L * i / n for i in range(n)]  # robot n-1's arc straddles s = L
    depths = [rng.uniform(0.3, 3.0) for _ in range(n)]
    history: list[list[AgentState]] = []
    for k in range(ticks):
        arcs = arc_lengths(bounds, RING_L)
        # each robot's own frame: its arc moved by its own whole turns
        states = [ring_state(i, k, bounds[i] + turns[i] * RING_L,
                             bounds[i] + arcs[i] + turns[i] * RING_L, depths[i], n)
                  for i in range(n)]
        history.append(states)
        new = ring_update(bounds, [s.workload for s in states], RING_L, K_S, MIN_SEG)
        bounds = [new[0] + RING_L] + new[1:] if new[0] < bounds[0] - 0.5 * RING_L else new
        depths = [max(0.3, d + rng.uniform(-0.05, 0.05)) for d in depths]
    for k in range(1, ticks):
        for i in range(n):
            s, before = history[k][i], history[k - 1][i]
            assert state_problem(s, RING_BOUNDS, k) is None
            for me, side in (((i + 1) % n, "lower"), ((i - 1) % n, "upper")):
                mine = {k - 1: claim(history[k - 1][me])}
                assert neighbour_problem(s, me, side, mine, before, MIN_SEG, RING_L) is None


def test_a_ring_state_off_the_law_by_other_than_whole_turns_is_refused() -> None:
    n = 3
    r1, r2 = ring_state(1, 4, 3.0, 6.0, 1.0, n), ring_state(2, 4, 6.0 - RING_L, 10.0 - RING_L,
                                                            0.5, n)
    mine = {4: claim(r2)}  # robot 2's frame is a turn below robot 1's
    law = ring_state(1, 5, 3.0, 6.02, 1.0, n)
    assert neighbour_problem(law, 2, "lower", mine, r1, MIN_SEG, RING_L) is None
    wrapped = ring_state(1, 5, 3.0 + RING_L, 6.02 + RING_L, 1.0, n)  # a whole turn: no jump
    assert neighbour_problem(wrapped, 2, "lower", mine, r1, MIN_SEG, RING_L) is None
    for hi in (6.0 + 0.5 * RING_L, 8.5, 4.2):  # half a turn, or beyond the law's reach
        moved = ring_state(1, 5, 3.0, hi, 1.0, n)
        why = neighbour_problem(moved, 2, "lower", mine, r1, MIN_SEG, RING_L)
        assert why is not None and "the law can put it only in" in why, hi
    # its bins lie near its arc; one across the ring is refused, as a chain's state is
    far = ring_state(1, 5, 3.0, 6.0, 1.0, n, end_bins=[80])
    assert "from its arc" in (state_problem(far, RING_BOUNDS, 5) or "")
    assert "open edge" in (state_problem(dataclasses.replace(law, closed=False),
                                         RING_BOUNDS, 5) or "")
    ring_on_chain = state(1, 5, 2.0, 4.0, closed=True)
    assert "closed edge's state on an open one" in (state_problem(ring_on_chain, BOUNDS, 5)
                                                    or "")
