"""The patrol's declared states and transitions: the table, that a run takes only
transitions it declares, and that each leg and arc starts with state of its own."""

from __future__ import annotations

import dataclasses
import math

import pytest

from agent.depthmap import DepthMap
from agent.patrol import (
    SUCCESSORS,
    TRANSITIONS,
    Arc,
    InLeg,
    Motion,
    OutLeg,
    Patrol,
    PatrolConfig,
    Steer,
    TeamInput,
    Tick,
)

UP = math.pi / 2


class Logged(Patrol):
    """A patrol that notes every transition it takes, and what each leg began with."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.taken: list[tuple[Motion, Motion]] = []
        self.entered: list[tuple[Motion, InLeg, OutLeg, Arc]] = []

    def _go(self, target: Motion, tick: Tick) -> bool:
        self.taken.append((self.motion, target))
        same_tick = super()._go(target, tick)
        self.entered.append((target, dataclasses.replace(self.in_leg),
                             dataclasses.replace(self.out_leg), dataclasses.replace(self.arc)))
        return same_tick


def drive(patrol: Patrol, sensed, steps: int, x: float = 0.55, y: float = -0.2,
          v: float = 0.05) -> list[Steer]:
    """Unit speed steps of ``v`` m along the patrol's steering; ``sensed(y)`` gives
    (ice, algae)."""
    theta, steers = UP, []
    for _ in range(steps):
        steer = patrol.step(x, y, theta, *sensed(y), 0.0, 2.0)
        theta += steer.curvature * v
        x += v * math.cos(theta)
        y += v * math.sin(theta)
        steers.append(steer)
    return steers


def ice_and_algae(y: float) -> tuple[bool, bool]:
    return y >= 0.0, 0.0 <= y < 0.6


def test_every_motion_has_its_declared_successors():
    assert SUCCESSORS == {
        Motion.ENTER: {Motion.UNDER, Motion.TURN_UNDER},  # the edge, or none found
        Motion.UNDER: {Motion.TURN_UNDER},
        Motion.TURN_UNDER: {Motion.EXIT},
        Motion.EXIT: {Motion.TURN_OUT},
        Motion.TURN_OUT: {Motion.ENTER},
    }
    for t in TRANSITIONS:  # every guard is a method of the patrol
        assert callable(getattr(Patrol, t.when)), t
    # only the arcs hand over to a leg that begins on the next tick
    assert {(t.source, t.target) for t in TRANSITIONS if not t.same_tick} == {
        (Motion.TURN_UNDER, Motion.EXIT), (Motion.TURN_OUT, Motion.ENTER)}


def test_a_run_takes_every_declared_transition_and_no_other():
    cfg = PatrolConfig()
    patrol = Logged(cfg, DepthMap(0.0, cfg.bin_m, cfg.min_depth_m), x=0.55)
    motions = [s.motion for s in drive(patrol, ice_and_algae, 400)]
    declared = {(t.source, t.target) for t in TRANSITIONS}
    assert set(patrol.taken) <= declared
    assert declared - set(patrol.taken) == {(Motion.ENTER, Motion.TURN_UNDER)}
    assert motions.count(Motion.TURN_OUT) > 0
    # no ice anywhere: every way in gives up after max_search_m and turns
    missed = Logged(cfg, DepthMap(0.0, cfg.bin_m, cfg.min_depth_m), x=0.55)
    drive(missed, lambda y: (False, False), 200)
    assert (Motion.ENTER, Motion.TURN_UNDER) in missed.taken
    assert (Motion.ENTER, Motion.UNDER) not in missed.taken
    assert set(missed.taken) <= declared


def test_an_undeclared_transition_is_refused():
    cfg = PatrolConfig()
    patrol = Patrol(cfg, DepthMap(0.0, cfg.bin_m, cfg.min_depth_m), x=0.55)
    tick = Tick(0.55, 0.0, UP, True, False, None, 0.0, 0.0, 2.0, TeamInput())
    with pytest.raises(ValueError, match="ENTER -> EXIT"):
        patrol._go(Motion.EXIT, tick)
    assert patrol.motion is Motion.ENTER


def test_each_leg_and_arc_begins_with_state_of_its_own():
    cfg = PatrolConfig()
    patrol = Logged(cfg, DepthMap(0.0, cfg.bin_m, cfg.min_depth_m), x=0.55)
    drive(patrol, ice_and_algae, 400)
    fresh_in = fresh_out = 0
    for target, in_leg, out_leg, arc in patrol.entered:
        if target is Motion.ENTER:  # a new way in: nothing of the last one is left
            assert in_leg == InLeg()
            fresh_in += 1
        elif target is Motion.EXIT:  # a new way out; the way in's edge is kept
            assert out_leg == OutLeg() and in_leg.entry_y is not None
            fresh_out += 1
        elif target in (Motion.TURN_UNDER, Motion.TURN_OUT):
            assert arc.turned == 0.0 and arc.sign in (-1, 1)
    assert fresh_in >= 2 and fresh_out >= 2


def test_the_edge_is_measured_on_the_tick_it_is_seen_and_a_leg_starts_the_tick_after():
    cfg = PatrolConfig()
    patrol = Patrol(cfg, DepthMap(0.0, cfg.bin_m, cfg.min_depth_m), x=0.55)
    assert patrol.step(0.55, -0.02, UP, False, False, 0.0, 2.0).motion is Motion.ENTER
    assert patrol.in_leg.start_y == -0.02 and patrol.in_leg.from_water
    # on the edge's tick UNDER decides too: the algae seen there counts
    assert patrol.step(0.55, 0.02, UP, True, True, 0.0, 2.0).motion is Motion.UNDER
    assert patrol.in_leg.entry_y == pytest.approx(0.0)
    assert patrol.in_leg.algae_depth == pytest.approx(0.02)
    # an arc that ends hands over to a leg whose first tick is the next one
    patrol = Logged(cfg, DepthMap(0.0, cfg.bin_m, cfg.min_depth_m), x=0.55)
    steers = drive(patrol, ice_and_algae, 400)
    for before, after in zip(steers, steers[1:], strict=False):
        if before.motion is Motion.TURN_UNDER and after.motion is Motion.EXIT:
            break
    else:
        raise AssertionError("no arc ended under the ice")
    assert [t for t, *_ in patrol.entered][:4] == [
        Motion.UNDER, Motion.TURN_UNDER, Motion.EXIT, Motion.TURN_OUT]


def test_the_view_is_read_only_and_follows_the_patrol():
    cfg = PatrolConfig()
    patrol = Patrol(cfg, DepthMap(0.0, cfg.bin_m, cfg.min_depth_m), x=0.55, direction=-1)
    view = patrol.view
    assert (view.motion, view.direction, view.grid_x, view.passes, view.turned) == (
        Motion.ENTER, -1, 0.55, cfg.passes_per_sweep, 0.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        view.direction = 1  # type: ignore[misc]


def test_the_team_passes_are_taken_only_at_a_new_sweep():
    cfg = PatrolConfig(passes_per_sweep=4)
    patrol = Patrol(cfg, DepthMap(0.0, 0.1, 0.3), x=2.9)
    patrol._start_turn(1.0, 3.0, heading_in=True, team=TeamInput(passes=9))
    assert patrol.sweeps == 1 and patrol.view.passes == 9
    patrol._start_turn(1.0, 3.0, heading_in=True, team=TeamInput(passes=5))
    assert patrol.sweeps == 1 and patrol.view.passes == 9  # within the sweep: kept
    patrol._start_turn(1.0, 3.0, heading_in=True)  # no team's number: the configured
    assert patrol.view.passes == 9


@pytest.mark.parametrize("bad", [
    {"arc_end_rad": 0.0}, {"max_arc_rad": 1.0}, {"past_edge_m": -0.1},
    {"min_last_pass": 0.0}, {"min_last_pass": 1.5}, {"arc_begun_rad": -0.01},
])
def test_the_named_arc_and_edge_constants_are_checked(bad):
    with pytest.raises(ValueError):
        PatrolConfig(**bad)
