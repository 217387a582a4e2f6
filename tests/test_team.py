"""What the team agrees on over neighbour-only messages (agent.team): chain maxima that
forget a need that left, passes per sweep with hysteresis, the root's rate; and the
agreement of a chain of control cores (agent.controller) on them."""

from __future__ import annotations

import math
import random

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from agent.controller import Controller, Gains, Neighbour, initial_segment
from agent.depthmap import DepthMap
from agent.patrol import Patrol, PatrolConfig, TeamInput
from agent.phase import leg_speed, position_to_phase
from agent.team import ChainMax, TeamRate, chain_max, cycle_for, passes_for, team_max

needs_st = st.lists(st.floats(0.01, 1000.0), min_size=2, max_size=20)


def chain_round(needs: list[float], prev: list[ChainMax | None]
                ) -> tuple[list[ChainMax], list[float]]:
    """One synchronous round of the neighbour-only update, as Controller._agree does
    it: every robot from its own value and its neighbours' of the previous round.
    Returns the new chain maxima and each robot's view of the team's maximum."""
    n = len(needs)
    new, seen = [], []
    for i, own in enumerate(needs):
        lower = prev[i - 1] if i > 0 else None
        upper = prev[i + 1] if i + 1 < n else None
        below = lower.below if lower is not None else None
        above = upper.above if upper is not None else None
        new.append(chain_max(own, below, above))
        seen.append(team_max(own, below, above))
    return new, seen


def exact_maxima(needs: list[float]) -> list[ChainMax]:
    return [ChainMax(max(needs[: i + 1]), max(needs[i:])) for i in range(len(needs))]


# --- 1. chain maxima ---------------------------------------------------------------


@settings(max_examples=50)
@given(needs_st)
def test_every_robot_knows_the_team_maximum_after_one_round_per_robot(needs):
    n = len(needs)
    state: list[ChainMax | None] = [None] * n
    for _ in range(n):
        state, seen = chain_round(needs, state)
    assert seen == [max(needs)] * n
    assert state == exact_maxima(needs)  # what each publishes: below / above itself


@settings(max_examples=50)
@given(needs_st)
def test_the_maximum_travels_one_robot_per_round_and_no_faster(needs):
    """A unique maximum at robot 0 reaches robot n-1 at round n, not before: the
    update is neighbour-only, and the bound of n rounds is tight."""
    n = len(needs)
    needs = [max(needs) + 1.0] + needs[1:]
    state: list[ChainMax | None] = [None] * n
    for r in range(1, n + 1):
        state, seen = chain_round(needs, state)
        # robot i has heard of robot 0 once r > i
        assert [s == needs[0] for s in seen] == [i < r for i in range(n)]


@settings(max_examples=50)
@given(needs_st, st.data())
def test_a_need_that_leaves_the_chain_is_forgotten_within_n_rounds(needs, data):
    n = len(needs)
    state: list[ChainMax | None] = [None] * n
    for _ in range(n):
        state, _ = chain_round(needs, state)
    top = needs.index(max(needs))
    if data.draw(st.booleans(), label="remove a robot"):
        # a robot dies (the largest need's, or any): its neighbours re-link, each
        # starting from the other's last published maxima, which still hold its need
        gone = data.draw(st.sampled_from([top, data.draw(st.integers(0, n - 1))]))
        needs = needs[:gone] + needs[gone + 1:]
        state = state[:gone] + state[gone + 1:]
    else:  # the hardest segment got easier
        needs = list(needs)
        needs[top] = data.draw(st.floats(0.001, 1.0)) * needs[top]
    for _ in range(n):
        state, seen = chain_round(needs, state)
    assert seen == [max(needs)] * len(needs)
    assert state == exact_maxima(needs)


@settings(max_examples=40)
@given(needs_st)
def test_a_naive_max_consensus_never_forgets_but_chain_maxima_do(needs):
    """x_i <- max(need_i, x_i, x_{i-1}, x_{i+1}) agrees as fast, but once the largest
    need leaves the team (its segment got easy) nothing ever lowers it again."""
    n = len(needs)
    needs = list(needs)
    top = needs.index(max(needs))
    needs[top] += 1.0  # a unique maximum
    old = needs[top]

    def naive_round(x: list[float]) -> list[float]:
        return [max(needs[i], *x[max(0, i - 1): i + 2]) for i in range(n)]

    naive = [0.0] * n
    state: list[ChainMax | None] = [None] * n
    for _ in range(n):
        naive = naive_round(naive)
        state, _ = chain_round(needs, state)
    assert naive == [old] * n
    needs[top] = 0.5 * min(needs)  # now the smallest: the true maximum is lower
    truth = max(needs)
    for _ in range(3 * n):
        naive = naive_round(naive)
        state, seen = chain_round(needs, state)
    assert naive == [old] * n  # stuck on the need that left
    assert seen == [truth] * n and truth < old


def test_team_max_takes_missing_neighbours_for_nothing():
    assert team_max(2.0, None, None) == 2.0
    assert team_max(2.0, 5.0, None) == 5.0 and team_max(2.0, None, 7.0) == 7.0
    assert chain_max(3.0, 1.0, 9.0) == ChainMax(3.0, 9.0)
    assert chain_max(3.0, None, None) == ChainMax(3.0, 3.0)


# --- 2. passes per sweep -------------------------------------------------------------

lengths = st.floats(0.01, 100.0)
spacings = st.floats(0.02, 2.0)


@settings(max_examples=50)
@given(lengths, spacings, st.integers(1, 60),
       st.none() | st.integers(1, 400), st.floats(0.0, 0.5))
def test_passes_never_too_few_nor_too_far_apart(longest, spacing, min_passes, current, hyst):
    p = passes_for(longest, spacing, min_passes, current, hyst)
    assert isinstance(p, int) and p >= min_passes
    assert longest / p <= spacing * (1 + 1e-9)
    # nor too many: kept only while one fewer would fit with less than hyst to spare
    assert p <= max(min_passes, math.ceil(longest / spacing - 1e-9),
                    longest / ((1 - hyst) * spacing) + 1 + 1e-9)


@settings(max_examples=50)
@given(lengths, spacings, st.integers(1, 60))
def test_passes_from_scratch_are_the_fewest_that_fit(longest, spacing, min_passes):
    p = passes_for(longest, spacing, min_passes)
    if p > min_passes:  # one fewer would leave passes too far apart
        assert longest / (p - 1) > spacing * (1 - 1e-9)


@settings(max_examples=50)
@given(st.integers(0, 2**32 - 1), st.integers(1, 40), st.integers(0, 40), spacings)
def test_a_length_hovering_at_a_threshold_does_not_flip_the_passes(seed, min_passes, k, spacing):
    """A random walk within +-1 % of k + min_passes passes' worth of spacing, 1000 steps:
    the passes change at most once."""
    k += min_passes
    rng = random.Random(seed)
    u, current, changes = 0.0, None, 0
    for _ in range(1000):
        u = min(0.01, max(-0.01, u + rng.uniform(-0.003, 0.003)))
        p = passes_for(k * spacing * (1 + u), spacing, min_passes, current)
        changes += current is not None and p != current
        current = p
    assert changes <= 1
    assert current in (k, k + 1)


def test_without_hysteresis_that_length_would_flip_every_step():
    flips = [passes_for(20 * 0.3 * (1.01 if i % 2 else 0.99), 0.3, 16,
                        21 if i % 2 == 0 else 20, hysteresis=0.0) for i in range(6)]
    assert flips == [20, 21] * 3
    hyst = [passes_for(20 * 0.3 * (1.01 if i % 2 else 0.99), 0.3, 16, 21) for i in range(6)]
    assert hyst == [21] * 6


@settings(max_examples=50)
@given(st.integers(1, 40), st.integers(0, 40), spacings, st.floats(0.0, 0.4),
       st.floats(0.001, 0.9))
def test_passes_drop_only_once_the_length_is_well_below(min_passes, k, spacing, hyst, drop):
    k += min_passes
    current = passes_for(k * spacing * 1.01, spacing, min_passes, hysteresis=hyst)
    assert current == k + 1
    # shrunk, but by less than the hysteresis: still k + 1
    within = k * spacing * (1 - hyst) * 1.001
    assert passes_for(within, spacing, min_passes, current, hyst) == current
    # shrunk by more: down to what fits, at once
    shrunk = k * spacing * (1 - hyst) * (1 - drop)
    lower = passes_for(shrunk, spacing, min_passes, current, hyst)
    assert lower < current and lower == passes_for(shrunk, spacing, min_passes)


@pytest.mark.parametrize("args", [
    (0.0, 0.3, 16), (-1.0, 0.3, 16), (5.0, 0.0, 16), (5.0, -0.3, 16), (5.0, 0.3, 0),
    (math.nan, 0.3, 16),
])
def test_passes_refuse_bad_inputs(args):
    with pytest.raises(ValueError):
        passes_for(*args)


def test_cycle_is_two_arcs_a_pass_with_the_margin():
    assert cycle_for(4.0, 16, 1.15) == pytest.approx(2 * 16 * 4.0 * 1.15)


# --- 3. the root's rate ---------------------------------------------------------------

cycles = st.floats(1.0, 200.0)


@settings(max_examples=50)
@given(cycles, st.floats(1.0001, 10.0), st.floats(0.01, 0.5))
def test_the_rate_rises_at_once(start, ratio, dt):
    rate = TeamRate()
    assert rate.update(start, dt) == start  # the first target is taken as it is
    assert rate.update(start * ratio, dt) == start * ratio
    assert rate.cycle_s == start * ratio


@settings(max_examples=40)
@given(st.floats(1.0, 50.0), st.floats(1.05, 4.0), st.floats(0.05, 0.5))
def test_the_rate_falls_slowly_without_undershooting(target, ratio, dt):
    start = target * ratio  # a tick is shorter than any cycle, as it is on the robots
    rate = TeamRate(start)
    gap0 = start - target
    steps = math.ceil(3 * start / dt)
    early = int(0.1 * target / dt)
    prev = start
    for k in range(1, steps + 1):
        now = rate.update(target, dt)
        assert target <= now <= prev  # monotone, never below the target
        if k == early:  # not at once: after a tenth of the target cycle, most to go
            assert now - target > 0.85 * gap0
        prev = now
    assert prev - target <= 0.05 * target  # within 5 % in three (start) cycles


@pytest.mark.parametrize("bad", [0.0, -5.0, math.nan])
def test_the_rate_refuses_a_target_that_is_not_positive(bad):
    rate = TeamRate(100.0)
    with pytest.raises(ValueError):
        rate.update(bad, 0.1)
    assert rate.cycle_s == 100.0
    with pytest.raises(ValueError):
        TeamRate().update(bad, 0.1)


# --- 4. a chain of control cores ------------------------------------------------------

# The boundaries stay put (k_s so small that no move survives rounding; the workload
# balance is tested elsewhere), so every robot's need and segment are fixed and the
# agreement on them can be checked exactly.
FROZEN = Gains(k_s=1e-300)
DT = 0.1


@st.composite
def teams(draw):
    n = draw(st.integers(2, 20))
    length = draw(st.floats(max(3.0, 0.6 * n), 30.0))
    # a depth sample in each robot's segment (where, how deep), or none
    samples = draw(st.lists(st.none() | st.tuples(st.floats(0.1, 0.9), st.floats(0.3, 3.0)),
                            min_size=n, max_size=n))
    return n, length, samples


def make_team(n: int, length: float, samples) -> list[Controller]:
    ctrls = []
    for i in range(n):
        lo, hi = initial_segment(i, n, 0.0, length)
        c = Controller(i, lo, hi, 0.0, length, 0.5 * (lo + hi), gains=FROZEN)
        if samples[i] is not None:
            where, depth = samples[i]
            c.depth_map.record(lo + where * (hi - lo), depth)
        ctrls.append(c)
    return ctrls


def lockstep(ctrls: list[Controller], ticks: int, dead_lower: Neighbour | None = None
             ) -> list[list[tuple[int, float]]]:
    """Step the chain in lockstep, each robot standing below the edge (y = -1, no ice
    nor algae) and seeing its neighbours' states of the previous tick. ``dead_lower``:
    the last state of a robot below the chain's first that has died (membership says
    it is gone, has_lower False). Returns each tick's (passes, cycle_s) per robot."""
    n = len(ctrls)
    published = [c.published for c in ctrls]
    history = []
    for _ in range(ticks):
        for i, c in enumerate(ctrls):
            lower = published[i - 1] if i > 0 else dead_lower
            upper = published[i + 1] if i + 1 < n else None
            c.step(DT, c.patrol.x, -1.0, math.pi / 2, False, False, lower, upper,
                   i > 0, i + 1 < n)
        published = [c.published for c in ctrls]
        history.append([(c.passes, c.cycle_s) for c in ctrls])
    return history


def need_of(c: Controller) -> float:
    return c.patrol.pass_need_s(c.lo, c.hi, c.limits.v_max, c.limits.wheel_base_m)


def assert_copies_with_lag(history, since: int) -> None:
    """Robot i's decision at tick t is the root's (robot 0 of ``history``) of tick t - i:
    the decision travels down the chain one robot per tick."""
    n = len(history[0])
    for t in range(since, len(history)):
        for i in range(1, n):
            if t - i >= since:
                assert history[t][i] == history[t - i][0], (t, i)


@settings(max_examples=6, deadline=None)
@given(teams())
@example((20, 30.0, [None] * 19 + [(0.5, 3.0)]))  # the hardest segment furthest away
@example((2, 30.0, [(0.5, 0.3), (0.5, 2.0)]))  # 15 m segments: more than the minimum
# robot 0's deep sample on a bin's side is not told to robot 1: the need dies with it
@example((3, 6.0, [(0.5, 3.0), None, None]))
def test_a_chain_of_controllers_agrees_on_the_roots_passes_and_cycle(team):
    n, length, samples = team
    ctrls = make_team(n, length, samples)
    cfg, margin = ctrls[0].patrol.config, FROZEN.cycle_margin
    ticks = max(50, 2 * n + 5)
    history = lockstep(ctrls, ticks)
    assert_copies_with_lag(history, 0)
    # the root hears the farthest need after n - 1 ticks, its decision reaches the
    # farthest robot n - 1 ticks later: from then on the chain agrees exactly
    for t in range(2 * n - 2, ticks):
        assert history[t] == [history[t][0]] * n, t
    passes, cycle = history[-1][0]
    longest = max(c.hi - c.lo for c in ctrls)
    assert passes * cfg.max_spacing_m >= longest - 1e-9
    assert passes == passes_for(longest, cfg.max_spacing_m, cfg.passes_per_sweep)
    assert cycle > 0
    max_need = max(need_of(c) for c in ctrls)
    assert cycle == pytest.approx(cycle_for(max_need, passes, margin), rel=1e-12)
    assert cycle == pytest.approx(2 * passes * max_need * margin, rel=1e-12)
    for c in ctrls:  # what each publishes: the chain maxima of the needs below and above
        i = c.robot
        assert c.published.need_below == max(need_of(d) for d in ctrls[: i + 1])
        assert c.published.need_above == max(need_of(d) for d in ctrls[i:])
        assert c.passes == passes  # what it tells its patrol (TeamInput.passes)

    # the root dies: robot 1 no longer has a lower neighbour (its last state is still
    # at hand, but membership says it is gone) and becomes the root
    before = history[-1][0]
    dead, ctrls = ctrls[0].published, ctrls[1:]
    m = len(ctrls)
    after = lockstep(ctrls, max(50, 2 * m + 5), dead_lower=dead)
    assert ctrls[0].lo == 0.0  # it took over the dead robot's segment
    assert_copies_with_lag(after, 0)
    for t in range(m - 1, len(after)):  # the new root's passes reach all within n ticks
        assert {p for p, _ in after[t]} == {after[t][0][0]}, t
    passes, cycle = after[-1][0]
    longest = max(c.hi - c.lo for c in ctrls)
    assert passes * cfg.max_spacing_m >= longest - 1e-9
    assert passes == passes_for(longest, cfg.max_spacing_m, cfg.passes_per_sweep, before[0])
    # the dead robot's need is forgotten along the chain
    live_max = max(need_of(c) for c in ctrls)
    assert ctrls[0].published.need_above == live_max
    assert all(c.published.need_below <= live_max for c in ctrls)
    target = cycle_for(live_max, passes, margin)
    cycles = [row[0][1] for row in after[m - 1:]]
    if target >= before[1]:  # a harder need: taken at once, and agreed within n ticks
        assert cycles == pytest.approx([target] * len(cycles), rel=1e-12)
        for t in range(m - 1, len(after)):
            assert after[t] == [after[t][0]] * m, t
    else:  # an easier one: the new root goes on from the old cycle, down slowly
        assert all(target < b <= a <= before[1] for a, b in zip(cycles, cycles[1:], strict=False))
        assert cycles[-1] > target + 0.5 * (before[1] - target)


@settings(max_examples=6, deadline=None)
@given(st.integers(2, 12), st.floats(0.0, 1.0), st.floats(1.0, 3.0), st.data())
def test_when_the_hardest_segment_gets_easier_the_chain_slows_down_together(n, at, deep, data):
    """One robot's segment holds the only deep column; it measures it again and finds
    it shallow. The chain forgets that need within n ticks, and the root's cycle comes
    down slowly from where it was, the chain following it one tick per robot."""
    length = data.draw(st.floats(max(3.0, 0.6 * n), 30.0), label="length")
    j = min(n - 1, int(at * n))
    samples = [None] * n
    samples[j] = (0.5, deep)  # mid-segment: no neighbour's segment holds that bin
    ctrls = make_team(n, length, samples)
    margin = FROZEN.cycle_margin
    history = lockstep(ctrls, 2 * n + 5)
    passes, before = history[-1][0]
    assert before == pytest.approx(cycle_for(need_of(ctrls[j]), passes, margin), rel=1e-12)
    c = ctrls[j]
    hardest = need_of(c)
    for _ in range(3):  # two of the last three samples outvote the deep one
        c.depth_map.record(c.lo + 0.5 * (c.hi - c.lo), c.patrol.config.min_depth_m)
    needs = [need_of(c) for c in ctrls]
    assert max(needs) < hardest  # the team's need came down
    target = cycle_for(max(needs), passes, margin)
    after = lockstep(ctrls, n)
    for c in ctrls:  # the old need is gone from every robot's chain maxima
        i = c.robot
        assert (c.published.need_below, c.published.need_above) == (
            max(needs[: i + 1]), max(needs[i:]))
    after += lockstep(ctrls, 60 - n)
    assert_copies_with_lag(after, 0)
    assert all(p == passes for row in after for p, _ in row)
    root = [row[0][1] for row in after]
    assert all(target < b <= a <= before for a, b in zip(root, root[1:], strict=False))
    assert root[-1] < before  # it does come down,
    assert root[-1] > target + 0.5 * (before - target)  # but not at once


# --- 5. pass geometry -------------------------------------------------------------------

CFG = PatrolConfig()
V_MAX, WHEEL_BASE = 0.5, 0.26
los, seg_lengths, team_passes = st.floats(0.0, 20.0), st.floats(0.3, 15.0), st.integers(1, 100)


def patrol_on(lo: float, passes: int) -> Patrol:
    patrol = Patrol(CFG, DepthMap(0.0, CFG.bin_m, CFG.min_depth_m), x=lo)
    patrol.passes = passes  # as latched at the start of a sweep
    return patrol


@settings(max_examples=50)
@given(los, seg_lengths, team_passes)
def test_the_passes_split_the_segment_exactly_and_step_the_phase_by_pi_over_passes(
        lo, length, passes):
    hi = lo + length
    patrol = patrol_on(lo, passes)
    spacing = patrol.spacing(lo, hi)
    assert spacing * passes == pytest.approx(hi - lo, rel=1e-14, abs=0)  # no clamp
    lines = [lo + j * spacing for j in range(passes + 1)]
    assert lines[-1] == pytest.approx(hi, rel=1e-14, abs=0)
    step = math.pi / passes
    up = [position_to_phase(x, lo, hi, 1) for x in lines]
    down = [position_to_phase(x, lo, hi, -1) for x in reversed(lines)]
    for phases in (up, down):  # the phase runs on by pi / passes, whichever the way
        for a, b in zip(phases, phases[1:], strict=False):
            assert (b - a) % (2 * math.pi) == pytest.approx(step, abs=1e-9)


def test_the_patrol_takes_the_teams_passes_only_at_a_new_sweep():
    patrol = Patrol(PatrolConfig(passes_per_sweep=4), DepthMap(0.0, 0.1, 0.3), x=1.05)
    while patrol.sweeps == 0:  # this sweep keeps its spacing
        assert patrol.spacing(1.0, 3.0) == 0.5
        patrol._start_turn(1.0, 3.0, heading_in=True, team=TeamInput(passes=7))
    assert patrol.passes == 7 and patrol.spacing(1.0, 3.0) == pytest.approx(2.0 / 7)


@settings(max_examples=50)
@given(los, seg_lengths, team_passes, seg_lengths, team_passes)
def test_an_arc_takes_longer_the_wider_the_spacing(lo, len_a, p_a, len_b, p_b):
    arcs = []
    for length, passes in ((len_a, p_a), (len_b, p_b)):
        patrol = patrol_on(lo, passes)
        arcs.append((patrol.spacing(lo, lo + length),
                     patrol.arc_time_s(lo, lo + length, V_MAX, WHEEL_BASE)))
    arcs.sort()
    (s_a, t_a), (s_b, t_b) = arcs
    assert 0 < t_a <= t_b
    # strictly so between the tightest and the widest arc the patrol makes
    lo_r, hi_r = CFG.min_turn_radius_m, 2 * CFG.max_turn_radius_m
    if lo_r < s_a < s_b < hi_r:
        assert t_a < t_b
        assert t_b - t_a == pytest.approx(math.pi * 0.5 * (s_b - s_a) / V_MAX)


@settings(max_examples=50)
@given(los, seg_lengths, team_passes, st.floats(0.0, 1.0), st.floats(0.0, 1.0),
       st.floats(CFG.min_depth_m, 4.0), st.floats(0.001, 2.0))
def test_the_pass_need_grows_with_the_deepest_depth(lo, length, passes, at_a, at_b,
                                                    depth, deeper):
    hi = lo + length
    patrol = patrol_on(lo, passes)
    need = patrol.pass_need_s(lo, hi, V_MAX, WHEEL_BASE)
    assert need > patrol.arc_time_s(lo, hi, V_MAX, WHEEL_BASE) > 0
    s_a = lo + at_a * length
    patrol.depth_map.record(s_a, depth)
    first = patrol.pass_need_s(lo, hi, V_MAX, WHEEL_BASE)
    assert first == pytest.approx(need + (depth - CFG.min_depth_m) / V_MAX)
    dm = patrol.depth_map
    s_b = lo + at_b * length
    if dm.bin_of(s_b) == dm.bin_of(s_a):  # another column: the middle of another bin
        centres = [(b + 0.5) * CFG.bin_m for b in range(dm.bin_of(lo), dm.bin_of(hi) + 1)]
        s_b = next(x for x in centres if lo <= x <= hi and dm.bin_of(x) != dm.bin_of(s_a))
    dm.record(s_b, depth + deeper)  # a deeper column
    second = patrol.pass_need_s(lo, hi, V_MAX, WHEEL_BASE)
    assert second > first
    assert second == pytest.approx(first + deeper / V_MAX)
    mid = lo + 0.5 * length
    if dm.bin_of(mid) not in (dm.bin_of(s_a), dm.bin_of(s_b)):
        dm.record(mid, CFG.min_depth_m)  # a shallow column changes nothing
        assert patrol.pass_need_s(lo, hi, V_MAX, WHEEL_BASE) == second


# --- 6. leg pacing --------------------------------------------------------------------


@settings(max_examples=50)
@given(st.floats(0.01, 5.0), st.floats(0.0, 1.0), st.floats(0.1, 1.0), st.floats(0.05, 1.5),
       st.floats(0.001, 0.05), st.floats(0.0, 1.0))
def test_a_paced_leg_ends_exactly_when_its_time_is_up(fast, slow, v_max, measure_ratio,
                                                      floor, where):
    """A leg paced at a speed between the floor and v_max covers its fast metres at
    that speed and its slow ones at the measuring speed in exactly the time left."""
    v_measure = measure_ratio * v_max  # may be above v_max: then v_max is the cap
    slow_v = min(v_max, v_measure)
    want = floor + where * (v_max - floor)  # a speed in [floor, v_max]
    time_left = fast / want + slow / slow_v
    v = leg_speed(time_left, fast, slow, False, v_max, v_measure, floor)
    assert floor <= v <= v_max
    if floor < v < v_max:
        assert fast / v + slow / slow_v == pytest.approx(time_left, abs=1e-9)
        assert v == pytest.approx(want, rel=1e-9)


@settings(max_examples=50)
@given(st.floats(-10.0, 100.0), st.floats(0.0, 5.0), st.floats(0.0, 1.0), st.booleans(),
       st.floats(0.1, 1.0), st.floats(0.01, 0.1), st.floats(0.001, 0.05))
def test_leg_speed_is_paced_floored_capped_and_full_once_late(time_left, fast, slow,
                                                              measuring, v_max, v_measure,
                                                              floor):
    v = leg_speed(time_left, fast, slow, measuring, v_max, v_measure, floor)
    cap = min(v_max, v_measure) if measuring else v_max
    assert min(floor, cap) <= v <= cap
    budget = time_left - slow / min(v_max, v_measure)
    if budget <= 0 or fast <= 0:  # late, or nothing left at speed: as fast as it may
        assert v == cap
    elif not measuring and floor < v < v_max:  # paced
        assert fast / v + slow / min(v_max, v_measure) == pytest.approx(time_left, abs=1e-9)


@pytest.mark.parametrize("longest, spacing", [(math.inf, 0.3), (math.nan, 0.3), (0.0, 0.3),
                                              (5.0, 0.0), (5.0, math.inf)])
def test_passes_for_refuses_what_no_segment_or_spacing_can_be(longest, spacing):
    with pytest.raises(ValueError, match="positive finite"):
        passes_for(longest, spacing, 16)
