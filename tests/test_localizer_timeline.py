"""The odometry between a filter's time and a scan measured between ticks
(localizer.timeline): shares of periods, nothing taken twice or lost."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hwbridge.runclock import tick_holding
from localizer.timeline import OdometryTimeline, advance


def timeline_with(motions: dict[int, list[tuple[float, float]]], at: float) -> OdometryTimeline:
    tl = OdometryTimeline(len(next(iter(motions.values()))), at=at)
    for k, rows in motions.items():
        for robot, (d, th) in enumerate(rows):
            assert tl.add(k, robot, d, th)
    return tl


def test_a_scan_on_the_tick_takes_its_period_whole_to_the_bit():
    tl = timeline_with({13: [(0.1 / 3, 0.07 / 3), (0.0, -0.01)]}, at=12.0)
    dist, dtheta = tl.take(13 * 0.1 / 0.1)
    assert dist.tolist() == [0.1 / 3, 0.0] and dtheta.tolist() == [0.07 / 3, -0.01]
    assert tl.at == 13.0 and not tl.periods


def test_a_scan_between_ticks_takes_the_share_of_its_period_and_leaves_the_rest():
    tl = timeline_with({13: [(0.05, 0.1)], 14: [(0.04, 0.0)]}, at=12.0)
    dist, dtheta = tl.take(12.4)
    assert dist[0] == pytest.approx(0.02) and dtheta[0] == pytest.approx(0.04)
    assert tl.at == 12.4 and 13 in tl.periods  # its rest is for the next scan
    dist, dtheta = tl.take(13.5)
    assert dist[0] == pytest.approx(0.03 + 0.02) and dtheta[0] == pytest.approx(0.06)
    assert list(tl.periods) == [14]


def test_odometry_the_filter_has_passed_is_refused():
    tl = OdometryTimeline(1, at=12.4)
    assert not tl.add(12, 0, 0.05, 0.0)  # (11, 12]: wholly behind
    assert tl.add(13, 0, 0.05, 0.0)  # (12, 13]: its last 0.6 is still ahead
    dist, _ = tl.take(13.0)
    assert dist[0] == pytest.approx(0.03)


def test_complete_needs_every_robots_odometry_of_every_period_up_to_the_scan():
    tl = OdometryTimeline(2, at=12.0)
    tl.add(13, 0, 0.05, 0.0)
    assert not tl.complete(12.5)  # robot 1's period 13 is missing
    tl.add(13, 1, 0.05, 0.0)
    assert tl.complete(12.5) and tl.complete(13.0) and not tl.complete(13.2)


def test_missing_odometry_counts_as_none():
    tl = timeline_with({13: [(0.05, 0.1)]}, at=12.0)
    dist, dtheta = tl.take(14.0)  # period 14 never came
    assert dist[0] == pytest.approx(0.05) and dtheta[0] == pytest.approx(0.1)


def test_ahead_is_what_take_would_take_and_takes_nothing():
    tl = timeline_with({13: [(0.05, 0.1)], 14: [(0.04, -0.2)]}, at=12.3)
    motions = tl.ahead(14.0)
    assert len(motions) == 2
    assert motions[0][0] == pytest.approx([0.7 * 0.05, 0.7 * 0.1])
    assert motions[1][0].tolist() == [0.04, -0.2]
    total = sum(motions)
    dist, dtheta = tl.take(14.0)
    assert (dist[0], dtheta[0]) == pytest.approx(tuple(total[0]))


@settings(max_examples=80, deadline=None)
@given(st.lists(st.tuples(st.floats(-0.05, 0.05), st.floats(-0.3, 0.3)), min_size=1,
                max_size=12),
       st.lists(st.floats(0.0, 1.0), min_size=1, max_size=8))
def test_scans_at_any_times_take_every_periods_motion_exactly_once(motions, cuts):
    start = 40.0
    tl = timeline_with({41 + j: [m] for j, m in enumerate(motions)}, at=start)
    end = start + len(motions)
    times = sorted(start + c * len(motions) for c in cuts) + [end]
    dist = dtheta = 0.0
    for t in times:
        d, th = tl.take(t)
        dist, dtheta = dist + d[0], dtheta + th[0]
    assert dist == pytest.approx(sum(m[0] for m in motions), abs=1e-12)
    assert dtheta == pytest.approx(sum(m[1] for m in motions), abs=1e-12)
    assert not tl.periods and tl.at == end


def test_advance_carries_a_pose_along_arcs_at_their_mid_heading():
    assert advance(1.0, 2.0, 0.0, []) == (1.0, 2.0, 0.0)
    x, y, th = advance(0.0, 0.0, 0.0, [(0.1, 0.0), (0.1, 0.0)])
    assert (x, y, th) == pytest.approx((0.2, 0.0, 0.0))
    x, y, th = advance(0.0, 0.0, 0.0, [(0.1, math.pi / 2)])
    assert (x, y, th) == pytest.approx((0.1 * math.cos(math.pi / 4),
                                        0.1 * math.sin(math.pi / 4), math.pi / 2))


def test_a_scan_belongs_to_the_tick_whose_sensing_covers_it():
    assert tick_holding(1.2, 0.1) == 12  # on the tick: that tick
    assert tick_holding(1.23, 0.1) == 13  # inside (1.2, 1.3]: tick 13's odometry covers it
    assert tick_holding(0.0, 0.1) == 0
    assert tick_holding(12345.6, 0.1) == 123456


def test_an_lms_scan_is_stamped_at_its_sweeps_middle_before_its_telegram():
    from hwbridge.lms_bridge import TURN_S, measured_times

    # 38400 baud, 8N1: a 734-byte telegram is 0.191 s on the line; 0.5 degrees: two turns
    (t,) = measured_times(100.0, 1, 734, 38400, 50)
    assert t == pytest.approx(100.0 - 7340 / 38400 - TURN_S)
    # two read at once: the first ended one telegram earlier
    first, second = measured_times(100.0, 2, 734, 38400, 50)
    assert second - first == pytest.approx(7340 / 38400)
    (one_degree,) = measured_times(100.0, 1, 734, 38400, 100)
    assert one_degree - t == pytest.approx(0.5 * TURN_S)
