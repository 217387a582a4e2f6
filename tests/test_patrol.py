"""The patrol state machine and depth map, and the whole control core closed around
the pure simulator (no bus): errors shrink, boundaries stay ordered."""

from __future__ import annotations

import dataclasses
import itertools
import math
import statistics
from collections.abc import Callable

import pytest

from agent.controller import Controller, Gains, Neighbour, initial_segment
from agent.depthmap import PRECISE, ROUGH, DepthMap
from agent.patrol import InLeg, Motion, Patrol, PatrolConfig, TeamInput
from agent.phase import position_to_phase, wrap_pi
from simworld.maps import load_map
from simworld.world import World


def test_depth_map_median_rejects_one_stray_sample():
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    for d in (1.2, 1.2, 0.4):  # the last leg strayed into the next column
        dm.record(0.55, d)
    assert dm.depths[5] == 1.2
    dm.record(0.55, 0.4)  # two of the last three agree: the profile changed
    assert dm.depths[5] == 0.4


def test_depth_map_average_fills_from_nearest_measurement():
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    assert dm.average(0.0, 1.0) == 0.3  # nothing measured yet
    dm.record(0.05, 1.5)
    dm.record(0.95, 0.3)
    # bins 0-4 nearest to bin 0 (1.5), bins 5-9 nearest to bin 9 (0.3); ties go up
    assert dm.average(0.0, 1.0) == pytest.approx((0.4 * 1.5 + 0.6 * 0.3) / 1.0, abs=0.13)
    assert dm.average(0.0, 0.1) == pytest.approx(1.5)


def drive(patrol: Patrol, track: list[tuple[float, float, bool, bool]], lo=0.0, hi=2.0):
    out = []
    for y, theta, ice, algae in track:
        out.append(patrol.step(0.5, y, theta, ice, algae, lo, hi).motion)
    return out


def test_patrol_asks_for_slow_legs_only_near_the_edges_it_measures():
    cfg = PatrolConfig()
    dm = DepthMap(0.0, 0.1, cfg.min_depth_m)
    patrol = Patrol(cfg, dm, x=0.55)
    up = math.pi / 2

    def measuring_along(depths: list[float]) -> list[bool]:
        patrol.motion, patrol.in_leg, patrol.prev_y = Motion.ENTER, InLeg(), None
        out = [patrol.step(0.55, -0.05, up, False, False, 0.0, 2.0).measuring]  # water
        for y in depths:
            out.append(patrol.step(0.55, y, up, True, True, 0.0, 2.0).measuring)
        return out

    # no ice edge known yet: fast on the way in; nothing measured in this column
    # yet: slow all the way under the ice
    assert measuring_along([0.05, 0.5, 1.0]) == [False, True, True, True]
    assert dm.edge_y(0.55) == pytest.approx(0.0)  # that leg found the edge at 0
    dm.record(0.55, 0.9)
    # slow from 8 cm before the known ice edge; under the ice fast until 8 cm before
    # the 0.9 m the map expects, slow to 8 cm past it
    assert measuring_along([0.05, 0.5, 0.83, 0.9, 0.97, 1.2]) == [
        True, False, False, True, True, True, False]
    assert measuring_along([]) == [True] and patrol.step(
        0.55, -0.1, up, False, False, 0.0, 2.0).measuring is False  # 10 cm out: fast
    with pytest.raises(ValueError):
        PatrolConfig(measure_speed=0.0)


def test_patrol_measures_depth_at_the_middle_of_the_algae_transition():
    cfg = PatrolConfig()
    dm = DepthMap(0.0, 0.1, cfg.min_depth_m)
    patrol = Patrol(cfg, dm, x=0.5)
    # approach: ice appears between y = -0.02 and 0.02 (edge at 0), algae to 0.9 m
    track = [(-0.1, math.pi / 2, False, False), (-0.02, math.pi / 2, False, False)]
    y = 0.02
    while y < 1.0:
        track.append((y, math.pi / 2, True, y < 0.9))
        y += 0.04
    motions = drive(patrol, track)
    assert motions[1] is Motion.ENTER and Motion.UNDER in motions
    assert patrol.last_depth == pytest.approx(0.9, abs=0.021)
    assert dm.depths[5] == pytest.approx(0.9, abs=0.021)
    # it goes on to turn_margin_m past the deepest algae it knows (the next pass line's
    # column is new), so the out-leg there starts below the algae and measures it
    turned = [y for (y, *_), mo in zip(track, motions, strict=True) if mo is Motion.TURN_UNDER]
    assert turned and turned[0] >= 0.9 + cfg.turn_margin_m - 0.02
    assert all(mo is Motion.UNDER for (y, *_), mo in zip(track, motions, strict=True)
               if 0.02 <= y < 0.93)


def test_patrol_without_algae_records_exactly_the_minimum_depth():
    cfg = PatrolConfig()
    dm = DepthMap(0.0, 0.1, cfg.min_depth_m)
    patrol = Patrol(cfg, dm, x=0.5)
    track = [(-0.05, math.pi / 2, False, False)] + [
        (0.01 + 0.045 * i, math.pi / 2, True, False) for i in range(10)
    ]
    drive(patrol, track)
    assert patrol.last_depth == cfg.min_depth_m


def test_sweep_reverses_inside_the_segment_and_reaches_its_end():
    patrol = Patrol(PatrolConfig(passes_per_sweep=4), DepthMap(0.0, 0.1, 0.3), x=1.05)
    lines = []
    for _ in range(12):
        patrol._start_turn(1.0, 3.0, heading_in=True)
        lines.append(patrol.grid_x)
    assert all(1.0 <= x <= 3.0 for x in lines)
    assert max(lines) == pytest.approx(3.0 - PatrolConfig().end_inset_m)
    assert patrol.sweeps >= 2


def unicycle(patrol: Patrol, sensed, x: float, y: float, steps: int, v: float = 0.05):
    """Drive the patrol's steering with unit speed steps of ``v`` m; ``sensed(x, y)``
    gives (ice, algae). Returns the track as (x, y, motion) per step."""
    theta, track = math.pi / 2, []
    for _ in range(steps):
        ice, algae = sensed(x, y)
        steer = patrol.step(x, y, theta, ice, algae, 0.0, 2.0)
        theta += steer.curvature * v
        x += v * math.cos(theta)
        y += v * math.sin(theta)
        track.append((x, y, steer.motion))
    return track


def test_a_pass_that_never_finds_the_edge_turns_back_and_moves_on():
    # a robot whose pose says it is on its segment but that is really off the ice's
    # end: no ice anywhere. It must not drive on for ever, nor record a depth.
    cfg = PatrolConfig(passes_per_sweep=8)
    dm = DepthMap(0.0, 0.1, cfg.min_depth_m)
    patrol = Patrol(cfg, dm, x=1.0)
    track = unicycle(patrol, lambda x, y: (False, False), 1.0, -1.0, 600)
    ys = [y for _, y, _ in track]
    assert max(ys) < -1.0 + cfg.max_search_m + 2 * cfg.max_turn_radius_m + 0.1
    assert min(ys) > -1.0 - 2 * cfg.max_turn_radius_m - 0.1  # back to where it began
    motions = [mo for *_, mo in track]
    assert motions.count(Motion.UNDER) == 0 and Motion.TURN_OUT in motions
    # several passes, each on a new pass line (x where each way in begins)
    starts = [round(x, 1) for (x, _, mo), (_, _, before) in
              zip(track[1:], track, strict=False) if mo is Motion.ENTER
              and before is not Motion.ENTER]
    assert len(starts) >= 3 and len(set(starts)) == len(starts)
    assert dm.depths == DepthMap(0.0, 0.1, cfg.min_depth_m).depths  # nothing recorded


def test_ice_that_never_ends_on_the_way_out_still_ends_the_leg():
    # under the ice everywhere past y = 0 (the edge is found, but going out the ice
    # never ends, as if the pose had drifted): the way out is bounded too
    cfg = PatrolConfig()
    patrol = Patrol(cfg, DepthMap(0.0, 0.1, cfg.min_depth_m), x=1.0)
    track = unicycle(patrol, lambda x, y: (y >= 0.0 or y < -1.5, False), 1.0, -1.0, 900)
    ys = [y for _, y, _ in track]
    assert min(ys) > -(cfg.max_depth_m + cfg.max_search_m) - 0.5
    assert [mo for *_, mo in track].count(Motion.TURN_OUT) >= 1


def closed_loop(map_name: str, start: str, seconds: float):
    """The control cores of a team around the pure simulator, neighbours' states one
    tick old, exactly as the processes exchange them."""
    gmap = load_map(map_name, 0.05, 1)
    world = World(gmap, 3, start, seed=1)
    info = world.info()
    e0, e1, bin_m, depth = info["edge_lo"], info["edge_hi"], info["bin_m"], info["patrol_depth"]

    def true_workload(lo: float, hi: float) -> float:
        total = 0.0
        for j, d in enumerate(depth):
            a, b = max(lo, e0 + j * bin_m), min(hi, e0 + (j + 1) * bin_m)
            total += max(0.0, b - a) * d
        return total

    ctrls = [Controller(i, *initial_segment(i, 3, e0, e1), e0, e1, world.truth(i)[0])
             for i in range(3)]
    published = [None, None, None]
    phase_err, work_err, segments = [], [], []
    for _ in range(int(seconds / 0.1)):
        outs = []
        for i, c in enumerate(ctrls):
            r = world.sense(i)
            x, y, th = world.truth(i)
            outs.append(c.step(0.1, x, y, th, r.ice, r.algae,
                               published[i - 1] if i > 0 else None,
                               published[i + 1] if i < 2 else None, i > 0, i < 2))
        published = [c.published for c in ctrls]
        xs = [world.truth(i)[0] for i in range(3)]
        ph = [position_to_phase(xs[i], o.lo, o.hi, o.direction) for i, o in enumerate(outs)]
        w = [true_workload(o.lo, o.hi) for o in outs]
        phase_err.append([abs(wrap_pi(ph[i + 1] - ph[i])) for i in range(2)])
        work_err.append([abs(w[i + 1] - w[i]) for i in range(2)])
        segments.append([(o.lo, o.hi) for o in outs])
        world.step({i: (o.v, o.omega) for i, o in enumerate(outs)}, 0.1)
    return phase_err, work_err, segments, ctrls


def quarter_means(rows):
    q = len(rows) // 4
    mean = lambda part: statistics.mean(itertools.chain.from_iterable(part))  # noqa: E731
    return mean(rows[:q]), mean(rows[-q:])


def test_core_closed_loop_half_algae_errors_shrink():
    phase, work, segments, _ = closed_loop("half-algae", "ahead:1", 600.0)
    p1, p4 = quarter_means(phase)
    w1, w4 = quarter_means(work)
    assert p4 < p1 / 4 and w4 < w1 / 4, (p1, p4, w1, w4)
    assert w4 < 0.015  # the thesis's half-algae cells are 0.015 to 0.019 m^2
    for segs in segments:  # every tick: ordered, no gap, no overlap, ends fixed
        assert segs[0][0] == 0.0 and segs[-1][1] == 6.0
        assert all(lo < hi for lo, hi in segs)
        assert all(a[1] == b[0] for a, b in zip(segs, segs[1:], strict=False))


def test_depth_map_staleness_prefers_unsampled_bins_and_ignores_bin_sides():
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    dm.record(0.05, 0.5)
    dm.record(0.25, 0.5)
    assert dm.staleness(0.05) == 1 and dm.staleness(0.25) == 0
    assert dm.staleness(0.15) > dm.staleness(0.05)  # never sampled beats any sampled
    assert dm.staleness(0.101) == 0  # a pass on a bin's side samples neither bin


def test_random_profile_every_column_of_each_segment_gets_measured():
    """Sweeps place their in-legs on the stalest columns: after 500 s every bin of each
    robot's segment that lies wholly inside it holds a measurement within 5 cm."""
    *_, ctrls = closed_loop("random-algae", "in-phase", 500.0)
    depth = load_map("random-algae", 0.05, 1).patrol_depth_bins(0.1)
    for c in ctrls:
        dm = c.depth_map
        whole = range(dm.bin_of(c.lo) + 1, dm.bin_of(c.hi))
        missing = [b for b in whole if b not in dm.depths]
        wrong = [(b, depth[b], dm.depths[b]) for b in whole
                 if b in dm.depths and abs(dm.depths[b] - depth[b]) > 0.05]
        assert not missing and len(wrong) <= 1, (c.robot, missing, wrong)


def test_depth_map_keeps_samples_of_the_best_kind_a_bin_has():
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    dm.record(0.101, 0.4)  # on the side of bin 1 (within SIDE_M): maybe bin 0's column
    assert dm.depths[1] == 0.4 and not dm.known(1)
    assert dm.staleness(0.15) > 10  # counts as never sampled: a pass there is wanted
    dm.record(0.15, 1.26, ROUGH)  # an out-leg at full speed, mid-bin
    assert dm.depths[1] == 1.26 and dm.known(1)
    dm.record(0.102, 0.4)  # a side sample no longer counts
    assert dm.depths[1] == 1.26
    dm.record(0.15, 1.21)  # a slow, precise one replaces the rough ones
    dm.record(0.15, 1.25, ROUGH)
    assert dm.depths[1] == 1.21
    for d in (1.2, 1.22, 1.9):  # the mean of the last three but the outermost two
        dm.record(0.14, d)
    assert dm.depths[1] == pytest.approx(1.22)


def test_depth_map_takes_the_ice_edge_from_many_crossings_nearby():
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    assert dm.edge_y(0.55) is None
    for i, err in enumerate((0.02, -0.024, 0.011, -0.007)):
        dm.cross(0.35 + 0.1 * i, 3.0 + err)  # bins 3 to 6
    assert dm.edge_y(0.55) == pytest.approx(3.0, abs=0.003)  # bins 2-8 pooled
    assert dm.edge_y(0.05) == pytest.approx(3.02)  # only bin 3 within three bins
    assert dm.edge_y(1.5) is None


def test_the_ice_edge_is_a_parabola_through_enough_crossings():
    """On a curved edge a line through +-0.35 m of crossings is millimetres off the
    bend, all one way; a parabola is not, once there are enough crossings to fit it."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    bend = lambda x: 1.0 + 0.3 * x - 0.8 * x * x  # noqa: E731
    for i in range(40):
        x = 0.02 + 0.05 * ((i * 0.618) % 1.0) * 14
        dm.cross(x, bend(x))
    for s in (0.05, 0.33, 0.61):
        assert dm.edge_y(s) == pytest.approx(bend(s), abs=1e-9)


def test_the_ice_edge_follows_a_sharp_bend_to_the_ends_of_a_robots_crossings():
    """A bend as sharp as the general suite draws (0.3 m high, 1.5 m long), crossed
    only inside one robot's segment: within a few millimetres up to the segment's ends
    (a parabola through +-0.35 m was 9 mm off its crest, and near the ends, where
    every crossing lies on one side, a line through them centimetres off)."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    bend = lambda x: 1.0 + 0.3 * math.sin(2 * math.pi * x / 1.5)  # noqa: E731
    for i in range(160):
        x = 1.0 + ((i * 0.618034) % 1.0)  # crossings over [1, 2] only, in no order
        dm.cross(x, bend(x))
    errors = [abs(dm.edge_y(s) - bend(s)) for s in [1.0 + 0.01 * k for k in range(101)]]
    assert max(errors) < 0.003
    assert statistics.mean(errors) < 0.0015


def test_a_straight_edge_is_fitted_with_a_line_not_a_cubic_through_the_noise():
    """Crossings of a sloped straight edge with a few millimetres of noise: a cubic
    would follow the noise; the F test keeps the line, and the slope."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    noise = (0.004, -0.003, 0.005, -0.004, 0.002, -0.005, 0.003, -0.002)
    xs = [0.3 + 0.05 * k for k in range(9)]
    for k, x in enumerate(xs):
        dm.cross(x, 1.0 + 0.1 * x + noise[k % len(noise)])
    fit = dm._fit_edge(dm.bin_of(0.5))
    assert fit is not None and len(fit) == 2  # a line
    assert fit[1] == pytest.approx(0.1, abs=0.02)


def test_a_leg_that_wobbled_across_a_step_on_a_bins_side_does_not_set_its_depth():
    """Columns of 0.36 m and 0.98 m meet on a bin's side (0.5 m). A sample taken right
    on that side by a leg that drifted across it reads between them; no sample near it
    agrees, and it is off the line between its neighbours: the profile leaves it out,
    and both bins come out at their columns' depths."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    for x in (0.405, 0.42, 0.44, 0.46, 0.475, 0.4825):
        dm.record(x, 0.36)
    for x in (0.503, 0.52, 0.54, 0.56, 0.58):
        dm.record(x, 0.98)
    dm.record(0.4999, 0.683)  # mixed
    assert dm.average(0.4, 0.5) == pytest.approx(0.36, abs=1e-9)
    assert dm.average(0.5, 0.6) == pytest.approx(0.98, abs=1e-9)


def test_a_lone_stray_sample_between_close_neighbours_is_left_out():
    """A sample 31 cm off the samples 2 cm either side of it, mid-bin (a leg still
    converging onto its line after an arc, on the next column's depth): no column
    that narrow is likely, so the profile leaves it out while its bin has other
    samples; alone in its bin it still counts."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    for x in (0.42, 0.435, 0.465, 0.48):
        dm.record(x, 0.5)
    dm.record(0.45, 0.81)  # the stray
    assert dm.average(0.4, 0.5) == pytest.approx(0.5, abs=1e-9)
    assert not dm.steps()
    alone = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    for x, d in ((0.36, 0.5), (0.45, 0.81), (0.54, 0.5)):
        alone.record(x, d)
    assert alone.average(0.4, 0.5) > 0.7


def test_a_lone_sample_on_a_bins_side_of_a_steep_ramp_is_kept():
    """On a ramp of 1.6 m per metre samples 4 cm apart differ by more than agree, but
    one on a bin's side lies on the line between its neighbours: it is the ramp, kept."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    ramp = lambda x: 0.3 + 1.6 * (x - 0.3)  # noqa: E731
    for x in (0.8625, 0.9005, 0.9375, 0.9625, 0.9875):
        dm.record(x, ramp(x))
    with_it = dm.average(0.9, 1.0)
    assert with_it == pytest.approx(ramp(0.95), abs=0.004)


def test_depths_are_measured_again_from_the_edge_the_crossings_give_now():
    """A sample keeps where the algae ended: as crossings come in, the edge its depth
    is measured from gets better, and so does the workload's profile."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    dm.cross(0.55, 2.01, ROUGH)  # the first crossing, 1 cm high
    dm.record(0.55, 0.99, top_y=3.0)  # from that edge: 0.99
    assert dm.average(0.5, 0.6) == pytest.approx(0.99)
    for _ in range(24):
        dm.cross(0.55, 2.0)  # slow crossings at 2.0 outweigh it
    assert dm.average(0.5, 0.6) == pytest.approx(1.0, abs=0.001)
    dm.record(0.45, 0.3, top_y=None)  # the minimum: not measured from the edge
    dm.record(0.52, 0.3, top_y=2.1)  # algae ending below the minimum: the minimum
    assert dm.average(0.4, 0.5) == pytest.approx(0.3)
    assert min(dm._profile()[2]) == pytest.approx(0.3)


def test_the_ice_edge_is_a_line_through_the_crossings_not_their_mean():
    """On a sloped edge the crossings near a robot's segment's end lie all on one
    side: their mean would put the edge (so every depth there) a slope times the
    offset out; the line through them does not, whatever their order."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    for x in (0.12, 0.31, 0.07, 0.26, 0.18, 0.33):
        dm.cross(x, 1.0 + 0.5 * x)
    assert dm.edge_y(0.04) == pytest.approx(1.02)
    assert dm.edge_y(0.29) == pytest.approx(1.145)
    dm.cross(0.2, 1.2, ROUGH)  # a crossing at full speed counts for less
    assert dm.edge_y(0.2) == pytest.approx(1.1, abs=0.01)


def test_neighbours_depths_fill_the_bins_a_robot_has_not_measured():
    lower = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    for s, d in ((1.65, 0.5), (1.75, 1.2), (1.95, 0.8), (1.05, 1.5)):
        lower.record(s, d)
    lower.record(1.801, 0.9)  # a side sample: not told to the neighbours
    ends = lower.near_ends(0.0, 2.0, 0.3)
    assert ends == ((17, 1.2), (19, 0.8))  # its measured bins within 0.3 m of 2.0
    upper = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    upper.record(2.25, 0.3)
    # [1.9, 2.5]: bin 19 from the neighbour, not from the nearest own bin (0.3)
    assert upper.average(1.9, 2.5) == pytest.approx((0.1 * 0.3 + 0.5 * 0.3) / 0.6)
    upper.learn(ends)
    assert upper.average(1.9, 2.5) == pytest.approx((0.1 * 0.8 + 0.5 * 0.3) / 0.6)
    upper.record(1.95, 0.85)  # its own measurement wins
    assert upper.average(1.9, 2.0) == pytest.approx(0.85)


def test_a_bin_off_the_edge_is_never_told_to_the_neighbours():
    """A leg that strayed past the edge's start (a hardware run's robot 0, 8 mm, its
    sample placed further out) sampled bin -1: every state its agent published after
    named it among
    its ends' depths, and its neighbour and the recorder refused them all (289 and 284
    states, "a bin of its ends is off the edge's 60 bins"), so the neighbour waited for
    it for the rest of the run. The map keeps the sample, and tells only the edge's
    bins."""
    from agent.plausible import Bounds, edge_bins

    bins = edge_bins(0.0, 6.0, 0.1)
    assert bins == Bounds(0.0, 6.0, 2.0, 0.1, 1).bins == 60
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3, bins=bins)
    for s, d in ((-0.05, 1.5), (0.05, 1.4), (5.95, 0.3), (6.05, 0.3)):
        dm.record(s, d)
    assert dm.known(-1) and dm.known(60)  # measured, for its own planning
    assert dm.near_ends(0.0, 6.0, 0.3) == ((0, 1.4), (59, 0.3))
    ctrl = Controller(0, 0.0, 2.0, 0.0, 6.0, 0.5)
    assert ctrl.depth_map.bins == edge_bins(0.0, 6.0, ctrl.depth_map.bin_m)


def test_a_sample_past_the_edges_end_is_not_in_the_workload():
    """A leg that strays past the edge's end (a 24.01 m edge, 0.7 mm past it) leaves
    the ice sideways and reads the algae ending there: the edge's last centimetre is
    as deep as the samples inside say, not as that one."""
    from agent.plausible import edge_bins

    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3, bins=edge_bins(0.0, 24.01, 0.1),
                  edge_hi=24.01)
    for s, d in ((23.95, 0.94), (23.99, 0.94), (24.0107, 0.56)):
        dm.record(s, d)
    assert dm.average(24.0, 24.01) == pytest.approx(0.94)
    assert dm.depths[240] == 0.56  # the bin keeps it, for the robot's own planning
    ctrl = Controller(0, 0.0, 2.0, 0.0, 6.0, 0.5)
    assert ctrl.depth_map.edge_hi == 6.0


def test_a_gap_in_the_profile_matters_only_between_different_depths():
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    for b in range(10):
        if b not in (3, 7):
            dm.record(0.1 * b + 0.05, 0.3 if b < 5 else 1.2)
    # bin 3 lies between two 0.3 m bins, bin 7 between two 1.2 m ones: no gap
    assert not dm.gap(0.0, 1.0)
    dm.record(0.501, 1.2)  # bin 5 has a side sample only (it may be bin 4's column)
    del dm.depths[5], dm.kind[5]
    dm.record(0.501, 1.2)
    assert not dm.known(5)
    assert dm.gap(0.0, 1.0)  # bin 5 lies between 0.3 (bin 4) and 1.2 (bin 6)
    assert not dm.gap(0.0, 0.5)  # outside [0, 0.5]
    dm.learn(((5, 1.2),))
    assert not dm.gap(0.0, 1.0)  # a neighbour's measurement counts


def test_every_robot_puts_its_pass_lines_on_the_same_grid_of_phases():
    """Robots with different segments starting a sweep at the same count of the team's
    sweep clock choose first passes whose lines take the same phases (eq. 3.1)."""
    levels = []
    for lo, hi in ((0.0, 1.2), (1.2, 2.4), (2.4, 6.0)):
        cfg = PatrolConfig()
        dm = DepthMap(0.0, 0.1, cfg.min_depth_m)
        patrol = Patrol(cfg, dm, x=hi - cfg.end_inset_m)
        # the sweep that begins at hi, going down
        patrol._start_turn(lo, hi, heading_in=True, team=TeamInput(clock=7.03))
        assert patrol.direction == -1 and patrol.sweeps == 1
        line, step = patrol.grid_x, patrol.spacing(lo, hi)
        phases = [position_to_phase(line - j * step, lo, hi, -1) for j in range(5)]
        levels.append([(p - math.pi) / (math.pi / cfg.passes_per_sweep) % 1.0 for p in phases])
    for a, b in itertools.combinations(levels, 2):
        assert a == pytest.approx(b, abs=1e-9)
    # the next sweep the same way (two counts on) puts the grid elsewhere
    cfg = PatrolConfig()
    patrol = Patrol(cfg, DepthMap(0.0, 0.1, cfg.min_depth_m), x=6.0 - cfg.end_inset_m)
    patrol._start_turn(2.4, 6.0, heading_in=True, team=TeamInput(clock=9.0))
    offset = (6.0 - patrol.grid_x) / patrol.spacing(2.4, 6.0) % 1.0
    assert offset != pytest.approx(levels[2][0], abs=0.05)


def test_a_line_is_aimed_at_the_nearest_new_column_within_reach_and_never_off_the_segment():
    """A pass line moves onto the middle of a column with no depth yet when one lies
    within aim_fraction of a pass, stays put on a new column's middle or with none in
    reach, never leaves legs further apart than cover_m, and the grid it is planned on
    does not move."""
    cfg = PatrolConfig(aim_fraction=0.25)
    dm = DepthMap(0.0, 0.1, cfg.min_depth_m)
    for b in range(30):
        if b not in (12, 13, 29):
            dm.record(0.1 * b + 0.05, 0.5)
    patrol = Patrol(cfg, dm, x=1.0)

    def aim(line: float, hi: float = 3.0, last: float | None = None) -> float:
        patrol.arc_from_x = line - patrol.spacing(0.0, hi) if last is None else last
        return patrol._aim(line, 0.0, hi)

    reach = 0.25 * patrol.spacing(0.0, 3.0)  # 0.25 * 0.1875 m
    assert aim(1.23) == 1.23  # within column 12's middle: stays
    assert aim(1.21) == pytest.approx(1.25)  # column 12, 0.04 away
    assert aim(1.39) == pytest.approx(1.35)  # 13 is nearer than 12
    assert aim(1.25 - reach - 0.001) == 1.25 - reach - 0.001  # too far
    assert aim(0.5) == 0.5  # nothing new near it
    assert aim(2.91, hi=2.98) == 2.91  # column 29's middle is past the end inset
    assert aim(2.91, hi=3.1) == pytest.approx(2.95)  # inside a longer segment
    assert aim(1.21, last=1.21 - cfg.cover_m) == 1.21  # 1.25 is too far from the last leg
    patrol.direction, patrol.arc_from_x = -1, 1.4  # going down: the next line is 1.0225
    assert patrol._aim(1.21, 0.0, 3.0) == pytest.approx(1.25)
    patrol.config = PatrolConfig(aim_fraction=0.25, max_spacing_m=0.2, cover_m=0.22)
    assert patrol._aim(1.21, 0.0, 3.0) == 1.21  # 1.25 would leave it 0.2275 off
    patrol.config, patrol.direction = cfg, 1
    dm.learn(((12, 0.7),))  # a neighbour's depth counts as known
    assert aim(1.21) == 1.21
    patrol.grid_x, patrol.line_x, patrol.direction = 1.3, 1.35, 1
    # from the grid, not the aimed line
    patrol._start_turn(0.0, 3.0, heading_in=True, team=TeamInput(clock=4.0))
    assert patrol.grid_x == pytest.approx(1.3 + patrol.spacing(0.0, 3.0))
    assert patrol.arc_from_grid == 1.3 and patrol.arc_from_x == 1.35


def test_a_robot_counts_sweeps_with_its_lower_neighbour():
    """The sweep clock of robot 1 is robot 0's, corrected by their phase difference,
    whatever robot 1 counted before (a robot restarted in a running team)."""
    ctrl = Controller(1, 2.0, 4.0, 0.0, 6.0, x=2.0)
    ctrl.step(0.1, 2.0, -0.3, math.pi / 2, False, False, None, None, False, False)
    own = ctrl.turns
    assert 0.0 <= own < 2 * math.pi
    lower = Neighbour(0, 0.0, 2.0, phase_des=ctrl.phase_des - 0.05, workload=0.6,
                      turns=40 * math.pi + ctrl.phase_des - 0.05)
    out = ctrl.step(0.1, 2.0, -0.3, math.pi / 2, False, False, lower, None, True, False)
    assert out.turns == pytest.approx(lower.turns + wrap_pi(out.phase_des - lower.phase_des))
    assert ctrl.clock == pytest.approx(out.turns / math.pi)
    assert round(ctrl.clock) == 40


def test_a_way_in_that_began_under_the_ice_measures_nothing():
    """A later way in that begins under the ice (an edge that bends below the pass
    line) crossed no edge, so neither the edge nor the depth of that leg is recorded."""
    cfg = PatrolConfig()
    dm = DepthMap(0.0, 0.1, cfg.min_depth_m)
    patrol = Patrol(cfg, dm, x=0.55)
    patrol.step(0.55, -0.5, math.pi / 2, False, False, 0.0, 2.0)  # its first tick: water
    patrol.in_leg = InLeg()  # a new way in, begun under the ice
    track = [(1.0 + 0.05 * i, math.pi / 2, True, i < 3) for i in range(12)]
    motions = drive(patrol, track)
    assert Motion.UNDER in motions and patrol.last_depth is not None
    assert dm.depths == {} and dm.crossings == {}


def test_an_agent_started_under_the_ice_goes_out_to_find_the_edge_first():
    """A restart finds its robot wherever it stood, here 2.4 m under the 3 m of ice of
    half-algae (y = 0 is the edge, y = 3 the map's far side) with nothing known. It
    turns and heads out, crosses the real edge and patrols it; it never reaches the
    ice's far side (which, going on deeper from where it stood, a 24-hour chaos run's
    restarted robots took for the edge and patrolled for good, 100 m off the map)."""
    gmap = load_map("half-algae")
    world = World(gmap, 1, "in-phase", seed=1, odom_noise=0.0)
    x0, y0, _ = world.truth(0)
    world.move(0, 1.0 - x0, 2.4 - y0)
    assert world.sense(0).ice
    ctrl = Controller(0, 0.0, 2.0, 0.0, 6.0, world.truth(0)[0])
    ys = []
    for _ in range(1200):
        x, y, th = world.truth(0)
        r = world.sense(0)
        out = ctrl.step(0.1, x, y, th, r.ice, r.algae, None, None, False, True)
        world.step({0: (out.v, out.omega)}, 0.1)
        ys.append(world.truth(0)[1])
    assert max(ys) < 2.4 + 2 * PatrolConfig().max_turn_radius_m
    assert min(ys) < -0.1  # it went out past the edge
    crossings = [y for seen in ctrl.depth_map.crossings.values() for _, y, _ in seen]
    assert crossings and all(abs(y) < 0.05 for y in crossings)  # the real edge
    assert max(ys[-300:]) < 1.5 + 0.3 + 2 * PatrolConfig().max_turn_radius_m


def test_a_robot_hurrying_to_catch_up_measures_nothing_slowly():
    cfg = PatrolConfig()
    dm = DepthMap(0.0, 0.1, cfg.min_depth_m)
    patrol = Patrol(cfg, dm, x=0.55)
    track = [(-0.1, math.pi / 2, False, False)] + [
        (-0.025 + 0.05 * i, math.pi / 2, True, i < 18) for i in range(22)]
    steers = [patrol.step(0.55, y, th, ice, algae, 0.0, 2.0, TeamInput(hurry=True))
              for y, th, ice, algae in track]
    assert not any(s.measuring for s in steers)  # not even in a column never measured
    assert dm.kind[5] == ROUGH  # its sample counts for less than a slow one
    dm.record(0.55, 0.9)
    assert dm.kind[5] == PRECISE and dm.depths[5] == 0.9


def test_a_controller_well_behind_its_desired_phase_hurries():
    ctrl = Controller(0, 0.0, 2.0, 0.0, 6.0, x=1.0)
    for _ in range(2):
        out = ctrl.step(0.1, 1.0, -0.3, math.pi / 2, False, False, None, None, False, False)
    assert not ctrl.hurry
    ctrl.phase_des = out.phase + 0.6  # the team is 0.6 rad ahead of this robot
    ctrl.step(0.1, 1.0, -0.3, math.pi / 2, False, False, None, None, False, False)
    assert ctrl.hurry


def test_a_neighbours_measurement_beats_a_sample_taken_on_the_bins_side():
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    dm.record(0.25, 1.4)
    dm.record(0.199, 0.77)  # bin 1's side: maybe bin 2's column
    assert dm.average(0.1, 0.2) == pytest.approx(0.77)  # better than nothing
    dm.learn(((1, 1.39),))
    assert dm.average(0.1, 0.2) == pytest.approx(1.39)


def test_the_arc_that_begins_a_sweep_steps_at_the_middle_of_its_step():
    """At a reversal the robot's phase at its line jumps (eq. 3.1 reads the same place
    from the other end); the arc waits for the middle between that phase and the next
    line's, as any arc, so robots whose last lines differ still step together."""
    ctrl = Controller(0, 0.0, 2.0, 0.0, 6.0, x=1.95)
    ctrl.step(0.1, 1.95, -0.4, -math.pi / 2, False, False, None, None, False, True)
    p = ctrl.patrol
    p.motion, p.arc_from_x, p.direction, p.line_x, p.turned = (
        Motion.TURN_OUT, 1.95, -1, 1.75, 0.0)
    p.arc_from_grid, p.grid_x = p.arc_from_x, p.line_x
    start = position_to_phase(1.95, 0.0, 2.0, -1)  # pi + 0.0785, not 3.06 going up
    middle = start + 0.5 * (position_to_phase(1.75, 0.0, 2.0, -1) - start)
    rate = 2 * math.pi / ctrl.cycle_s
    # the arc starts half its own duration early, so that its middle is the step's
    early = 0.5 * rate * p.arc_time_s(0.0, 2.0, ctrl.limits.v_max, ctrl.limits.wheel_base_m)
    for lead, moving in ((-0.01, False), (0.01, True)):
        assert ctrl.published is not None  # the desired phase goes on from what it published
        ctrl.published = dataclasses.replace(
            ctrl.published, phase_des=middle - early + lead - rate * 0.1)
        out = ctrl.step(0.1, 1.95, -0.4, -math.pi / 2, False, False, None, None, False, True)
        assert (out.v > 0) is moving, (lead, out.phase_des, middle)


def test_even_legs_turn_at_the_segments_deepest_depth():
    """With ``even_legs`` every in-leg goes on to the deepest depth known on the
    segment before it turns (all of a robot's passes as long); without, past the algae
    expected under the next line."""
    reached = {}
    for even in (False, True):
        cfg = PatrolConfig(passes_per_sweep=8, even_legs=even)
        dm = DepthMap(0.0, 0.1, cfg.min_depth_m)
        for b in range(20):  # the segment [0, 2] known: bare ice but one deep column
            dm.record(0.1 * b + 0.05, 1.2 if b == 15 else 0.3)
        patrol = Patrol(cfg, dm, x=0.55)
        track = unicycle(patrol, lambda x, y: (y >= 0.0, False), 0.55, -0.5, 60)
        first_turn = next(i for i, (*_, mo) in enumerate(track) if mo is Motion.TURN_UNDER)
        reached[even] = max(y for _, y, _ in track[: first_turn + 1])
    assert reached[False] < 0.45
    assert reached[True] > 1.2


def test_an_arc_ends_on_its_legs_heading_even_on_a_tight_segment():
    """A 0.3 m segment's passes are 2 cm apart: each arc turns about a point near the
    inner wheel, a third of a radian a tick at full speed. Its last tick goes no
    further than onto the leg's heading, so every leg begins square to the edge (a
    centimetre off its line is a tenth of a radian of eq. 3.1's phase there)."""
    gmap = load_map("no-algae")
    world = World(gmap, 1, "in-phase", seed=1, odom_noise=0.0)
    world.move(0, 2.05 - world.truth(0)[0], 0.0)
    gains = Gains(k_s=1e-9)
    ctrl = Controller(1, 2.0, 2.3, 0.0, 6.0, world.truth(0)[0], gains)
    lower = Neighbour(0, 0.0, 2.0, 0.0, 0.6)
    upper = Neighbour(2, 2.3, 6.0, 0.0, 0.6)
    starts, prev = [], None
    for _ in range(2000):
        x, y, th = world.truth(0)
        r = world.sense(0)
        lower = dataclasses.replace(lower, phase_des=ctrl.phase_des or 0.0)
        upper = dataclasses.replace(upper, phase_des=ctrl.phase_des or 0.0)
        out = ctrl.step(0.1, x, y, th, r.ice, r.algae, lower, upper, True, True)
        if prev in (Motion.TURN_UNDER, Motion.TURN_OUT) and out.motion in (
                Motion.ENTER, Motion.EXIT):
            heading = math.pi / 2 if out.motion is Motion.ENTER else -math.pi / 2
            starts.append(abs(wrap_pi(th - heading)))
        prev = out.motion
        world.step({0: (out.v, out.omega)}, 0.1)
    assert len(starts) >= 10
    assert max(starts) < 0.05, starts


def test_a_step_inside_a_bin_is_placed_between_the_samples_either_side_of_it():
    """Algae that steps from 0.5 m to 1.5 m at x = 0.145, inside bin 1: the bin's one
    value (its samples' median) would give the whole bin 1.5 m, 0.045 m^2 of workload
    out; the samples, each where it was taken, place the step half way between
    0.13 and 0.16, and the noise of two samples on one side averages out."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    for x, d in ((0.16, 1.5), (0.105, 0.49), (0.175, 1.5), (0.13, 0.51)):
        dm.record(x, d)
    assert dm.average(0.1, 0.2) == pytest.approx(1.05)
    assert dm.average(0.1, 0.145) == pytest.approx(0.5)
    assert dm.average(0.0, 0.1) == pytest.approx(0.5)  # the nearest sample's, beyond


def test_samples_that_agree_make_their_bin_one_column():
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    for x, d in ((0.12, 0.8), (0.18, 0.8), (0.25, 1.2), (0.27, 1.2)):
        dm.record(x, d)
    assert dm.average(0.1, 0.2) == pytest.approx(0.8)
    assert dm.average(0.2, 0.3) == pytest.approx(1.2)
    assert dm.average(0.15, 0.25) == pytest.approx(1.0)
    assert dm.average(0.4, 0.6) == pytest.approx(1.2)  # beyond the last: its depth


def _late_sensor_leg(cfg: PatrolConfig, offset: float) -> float:
    """One in-leg across the ice edge (y = 0) at 5 cm a tick and across the algae's end
    (y = 0.9) at 1 cm a tick, read by sensors half a tick late through comparators with
    a 2 cm dead band (as the lab profile's); the depth the patrol records. ``offset``
    moves where the ticks fall."""
    dm = DepthMap(0.0, 0.1, cfg.min_depth_m)
    patrol = Patrol(cfg, dm, x=0.5)
    ys = [-0.3 + offset + 0.05 * i for i in range(14)]
    while ys[-1] < 0.8:
        ys.append(ys[-1] + 0.05)
    while ys[-1] < 1.0:
        ys.append(ys[-1] + 0.01)  # slow over the algae's end
    ice = algae = False
    for prev, y in zip([ys[0]] + ys, ys, strict=False):
        at = 0.5 * (prev + y)  # where the robot was half a tick ago
        ice = at > 0.01 if not ice else at > -0.01  # switches at +-1 cm
        inside = min(at, 0.9 - at)
        algae = inside > 0.01 if not algae else inside > -0.01
        patrol.step(0.5, y, math.pi / 2, ice, algae and ice, 0.0, 2.0, TeamInput(dt=0.1))
    assert patrol.last_depth is not None
    return patrol.last_depth


def test_late_sensors_with_a_dead_band_are_placed_back_by_what_the_agent_is_told():
    """Told nothing, a leg finds the edge 3.5 cm in (fast) and the algae's end 1.5 cm
    past it (slow): 2 cm short on average over where the ticks fall. Told the latency
    and the band, right on average, each leg within the ticks' spacing."""
    told = dataclasses.replace(PatrolConfig(), sensor_latency_s=0.05, sensor_band_m=0.02)
    offsets = [0.05 * i / 20 for i in range(20)]
    plain = [_late_sensor_leg(PatrolConfig(), o) - 0.9 for o in offsets]
    placed = [_late_sensor_leg(told, o) - 0.9 for o in offsets]
    assert statistics.mean(plain) == pytest.approx(-0.02, abs=0.003)
    assert statistics.mean(placed) == pytest.approx(0.0, abs=0.002)
    assert max(map(abs, placed)) <= 0.026  # half a fast tick, and the slow one's half
    with pytest.raises(ValueError):
        PatrolConfig(sensor_latency_s=-0.01)


def test_a_column_an_out_leg_started_in_is_at_least_that_deep():
    """An out-leg that starts inside algae sees no end to it: the column reaches at
    least that deep. Until it is measured the profile takes it at least that deep (not
    as deep as its neighbours), it matters for aiming, and even legs go that deep."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    for b in (0, 2):
        dm.record(0.1 * b + 0.05, 0.3)
    assert dm.average(0.1, 0.2) == pytest.approx(0.3)  # taken for its neighbours' depth
    assert not dm.gap(0.0, 0.3)
    patrol = Patrol(PatrolConfig(), dm, x=0.15)
    dm.cross(0.15, 0.0)
    patrol.motion = Motion.EXIT
    patrol.step(0.15, 1.4, -math.pi / 2, True, True, 0.0, 0.3)  # algae from its start
    assert dm.floors == {1: pytest.approx(1.4)}
    assert dm.average(0.1, 0.2) == pytest.approx(1.4)
    assert dm.gap(0.0, 0.3)  # a column deeper than it was taken for: aim at it
    assert patrol.deepest(0.0, 0.3) == pytest.approx(1.4)
    dm.floor(0.15, 1.2)  # a shallower bound says nothing new
    assert dm.floors[1] == pytest.approx(1.4)
    dm.record(0.15, 1.5)  # measured at last: the bound has done its work
    assert dm.floors == {} and dm.average(0.1, 0.2) == pytest.approx(1.5)
    dm.floor(0.15, 1.6)  # nor does a bound once the column is measured
    assert dm.floors == {}


def test_a_sample_measured_from_a_better_edge_does_not_look_like_a_change():
    """Two samples of one column whose algae ended at the same place agree, however
    far apart the edges they were first measured from: the first edge, from a single
    crossing 15 cm high, is 15 cm off, but the map compares depths from the edge the
    crossings give now (a static map taken for a changing one forgot most of its
    samples)."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    dm.cross(0.55, 0.15, ROUGH)
    dm.record(0.551, 0.85, top_y=1.0)  # 0.85 from the edge it knew then
    for _ in range(24):
        dm.cross(0.55, 0.0)  # the edge is at 0
    for k in range(4):
        dm.record(0.552 + 0.001 * k, 1.0, top_y=1.0)  # 1.0 from it, the same algae
        dm.tick(0.1, 100.0)
    assert dm.contradicted is None and not dm.changing


def test_the_widest_step_not_yet_placed_is_the_one_a_leg_is_aimed_at():
    """Two steps between samples that disagree: 0.4 m to 1.0 m between 0.13 and 0.16
    (3 cm x 0.6 m) and 1.0 m to 0.3 m between 0.25 and 0.355 (10.5 cm x 0.7 m). The leg
    goes where a sample takes the most error off (rise x (aim - a)(z - aim) / width): the
    middle of a stretch, or of its part inside the window; off a bin's side by
    AIM_SIDE_M; and nowhere once a stretch is under RESOLVE_M."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    for s, d in ((0.02, 0.4), (0.08, 0.4), (0.13, 0.4), (0.16, 1.0), (0.25, 1.0),
                 (0.355, 0.3), (0.45, 0.3)):
        dm.record(s, d, PRECISE)
    assert [(a, z) for a, z, _, _ in dm.steps()] == [(0.13, 0.16), (0.25, 0.355)]
    assert dm.step_target(0.0, 0.5) == pytest.approx(0.305)  # 0.3025: 0.30 is a bin's side
    assert dm.step_target(0.0, 0.26) == pytest.approx(0.145)  # the wide one's 1 cm: less
    assert dm.step_target(0.0, 0.27) == pytest.approx(0.26)  # its 2 cm: more
    assert dm.step_target(0.31, 0.5) == pytest.approx(0.3325)  # its part in [0.31, 0.5]
    assert dm.step_target(0.0, 0.1) is None and dm.step_target(0.5, 0.9) is None
    assert dm.expected_depths(0.15) == (0.4, 1.0)  # either side of the open step
    assert dm.expected_depths(0.2) == (1.0,)  # the bin's own
    assert dm.expected_depths(0.75) == ()  # no depth there yet
    dm.record(0.143, 0.4, PRECISE)
    dm.record(0.147, 1.0, PRECISE)  # 0.143 to 0.147: placed to 4 mm
    assert dm.step_target(0.1, 0.2) is None
    assert dm.expected_depths(0.145) == (dm.depths[1],)  # placed: the bin's depth


def test_a_ramp_whose_samples_disagree_is_no_step_to_aim_at():
    """On a ramp of 1.6 m per metre samples 4 cm apart disagree, each with both its
    neighbours: no step (a leg aimed between two would only sample the ramp again),
    and a leg there expects one depth, not two."""
    dm = DepthMap(edge_lo=0.0, bin_m=0.1, default_m=0.3)
    for k in range(12):
        x = 0.305 + 0.04 * k
        dm.record(x, 0.3 + 1.6 * (x - 0.3), PRECISE)
    assert dm.steps() == [] and dm.step_target(0.3, 0.8) is None
    assert len(dm.expected_depths(0.52)) == 1


def test_a_leg_with_no_new_column_in_reach_is_aimed_at_a_step_within_aim_fraction():
    """With every column measured, a pass line moves onto a step of the profile that
    is not yet placed, by at most aim_fraction of a pass (and within cover_m); with
    aim_steps off it stays on its line."""
    cfg = PatrolConfig()
    dm = DepthMap(0.0, 0.1, cfg.min_depth_m)
    for b in range(100):
        dm.record(0.1 * b + 0.05, 0.5 if b < 50 else 1.2)  # a step between 4.95 and 5.05
    patrol = Patrol(cfg, dm, x=4.9)
    patrol.passes = 40  # 0.25 m apart

    def aim(line: float) -> float:
        patrol.arc_from_x = line - 0.25
        return patrol._aim(line, 0.0, 10.0)

    reach = cfg.aim_fraction * 0.25  # 6.25 cm
    assert aim(5.08) == pytest.approx(0.5 * (5.08 - reach + 5.05))  # its part in reach
    assert aim(4.91) == pytest.approx(0.5 * (4.95 + 4.91 + reach))
    assert aim(5.003) == pytest.approx(5.005)  # off the bin's side at 5.0
    assert aim(4.96) == pytest.approx(0.5 * (4.95 + 4.96 + reach))
    assert aim(5.05 + reach + 0.001) == 5.05 + reach + 0.001  # out of reach
    assert aim(2.0) == 2.0  # no step near
    patrol.config = PatrolConfig(aim_steps=False)
    assert aim(5.08) == 5.08


def test_a_leg_on_a_step_not_yet_placed_measures_slowly_near_both_its_depths():
    """Under the ice on a step between 0.4 m and 1.0 m that its samples do not yet
    place, the leg goes slowly near either depth, and to_go counts both zones once."""
    cfg = PatrolConfig()
    dm = DepthMap(0.0, 0.1, cfg.min_depth_m)
    for s, d in ((0.11, 0.4), (0.19, 1.0), (0.55, 1.0)):  # (the last: legs go to 1.0)
        dm.record(s, d, PRECISE)
    dm.cross(0.15, 0.0)
    patrol = Patrol(cfg, dm, x=0.15)
    patrol.motion, patrol.in_leg = Motion.UNDER, InLeg(entry_y=0.0, from_water=True)
    patrol.x = 0.15
    slow = [patrol._measuring(0.15, y, False) for y in (0.2, 0.4, 0.7, 1.0, 1.2)]
    assert slow == [False, True, False, True, False]
    fast, slow_m = patrol.to_go(0.0, 0.0, 2.0)
    assert slow_m == pytest.approx(2 * cfg.measure_zone_m)
    patrol.x = 0.12  # a bin's own depth, 0.4 m... of the step's left side
    assert patrol._measuring(0.12, 1.0, False) is True  # still inside the open step


def test_an_aimed_leg_begins_on_the_line_it_is_aimed_at():
    """The arc onto a leg aimed off its grid line (a new column, a step) is sized for
    the aimed line, so the leg starts on it: sized for the grid line, an out-leg that
    turned under the ice was still 2 cm off when it met the algae's end, and recorded
    its sample there instead of on the step it was aimed at."""
    gmap = load_map("random-algae", 0.05, 1)
    world = World(gmap, 2, "in-phase", seed=1)
    info = world.info()
    e0, e1 = info["edge_lo"], info["edge_hi"]
    ctrls = [Controller(i, *initial_segment(i, 2, e0, e1), e0, e1, world.truth(i)[0])
             for i in range(2)]
    published: list[Neighbour | None] = [None, None]
    arcs = (Motion.TURN_OUT, Motion.TURN_UNDER)
    was = [c.patrol.motion for c in ctrls]
    starts = []  # (how far the leg's first tick is from its line, how far it was aimed)
    for _ in range(3000):
        outs = []
        for i, c in enumerate(ctrls):
            r = world.sense(i)
            x, y, th = world.truth(i)
            outs.append(c.step(0.1, x, y, th, r.ice, r.algae, published[1 - i] if i else None,
                               None if i else published[1], i > 0, i < 1))
            p = c.patrol
            if was[i] in arcs and p.motion not in arcs:
                starts.append((abs(x - p.line_x), abs(p.line_x - p.grid_x)))
            was[i] = p.motion
        published = [c.published for c in ctrls]
        world.step({i: (o.v, o.omega) for i, o in enumerate(outs)}, 0.1)
    aimed = [off for off, by in starts if by > 0.02]
    assert len(aimed) >= 5, starts
    assert max(aimed) < 0.01, sorted(aimed)


def test_legs_cross_the_edge_at_every_offset_from_their_ticks():
    """A leg measuring at 0.1 m/s moves 1 cm a tick, and the edge is taken at the
    middle of the two ticks about it: if leg after leg crossed at the same offset from
    its ticks, every crossing would be off the same way (on half-algae without
    ``refined_measuring`` two robots of three averaged 1.1 and 1.2 mm above the edge). The
    first tick of each slow stretch puts the ticks at a new offset: every robot's
    crossings fall over the whole tick, and their mean is on the edge. (Off by
    default: see PatrolConfig.refined_measuring.)"""
    gmap = load_map("half-algae", 0.05, 1)
    n = 3
    world = World(gmap, n, "in-phase", seed=1)
    info = world.info()
    e0, e1 = info["edge_lo"], info["edge_hi"]
    cfg = PatrolConfig(refined_measuring=True)
    ctrls = [Controller(i, *initial_segment(i, n, e0, e1), e0, e1, world.truth(i)[0],
                        patrol=cfg) for i in range(n)]
    offsets: list[list[float]] = [[] for _ in range(n)]  # (the middle - the edge) / tick
    for i, c in enumerate(ctrls):
        def cross(s: float, y: float, kind: int = PRECISE, i: int = i,
                  record: Callable[..., None] = c.depth_map.cross) -> None:
            if kind == PRECISE:
                offsets[i].append((y - gmap.edge_y(s)) / 0.01)
            record(s, y, kind)
        c.depth_map.cross = cross  # type: ignore[method-assign]
    published: list[Neighbour | None] = [None] * n
    for _ in range(12000):
        outs = []
        for i, c in enumerate(ctrls):
            r = world.sense(i)
            x, y, th = world.truth(i)
            outs.append(c.step(0.1, x, y, th, r.ice, r.algae,
                               published[i - 1] if i else None,
                               published[i + 1] if i + 1 < n else None, i > 0, i + 1 < n))
        published = [c.published for c in ctrls]
        world.step({i: (o.v, o.omega) for i, o in enumerate(outs)}, 0.1)
    for seen in offsets:
        assert len(seen) >= 60
        assert all(-0.5 <= f <= 0.5 for f in seen)
        assert abs(statistics.fmean(seen)) < 0.06, statistics.fmean(seen)  # 0.6 mm
        fifths = [sum(-0.5 + 0.2 * j <= f < -0.3 + 0.2 * j for f in seen) for j in range(5)]
        assert min(fifths) >= 0.12 * len(seen), fifths


def test_a_slope_sampled_unevenly_is_integrated_as_the_line_it_is():
    """A bloom's side sampled in clusters (as legs fall) with a gap between them: each
    sample is smoothed along the line through the samples near it, not to their mean,
    which held the cluster's middle across the gap (before, 0.13 mm^2 too much over
    these 9 cm). Samples either side of a step stay where they are."""
    def depth(s: float) -> float:
        return 1.2 - (s - 0.2)  # 1 cm of depth a cm along the edge

    dm = DepthMap(0.0, 0.1, 0.3, refined=True)
    places = ([0.305 + 0.004 * k for k in range(7)] + [0.362]
              + [0.38 + 0.003 * k for k in range(6)])
    for s in places:
        dm.record(s, depth(s), PRECISE)
    a, z = places[0], places[-1]
    assert dm.average(a, z) * (z - a) == pytest.approx(0.5 * (depth(a) + depth(z)) * (z - a),
                                                       abs=1e-6)
    steps = DepthMap(0.0, 0.1, 0.3, refined=True)
    for s in (0.72, 0.74, 0.76, 0.775, 0.79, 0.81, 0.83, 0.85):
        steps.record(s, 0.4 if s < 0.8 else 1.1, PRECISE)
    assert steps.average(0.72, 0.85) == pytest.approx((0.08 * 0.4 + 0.05 * 1.1) / 0.13)


def test_a_fast_sample_on_a_bins_side_between_two_depths_is_left_out():
    """A sample taken at full speed (ROUGH, a tick of 5 cm) on a bin's side between two
    columns reads between them, near the line between its neighbours: where its bin
    has other samples it is left out of the profile. Fast samples elsewhere are kept."""
    dm = DepthMap(0.0, 0.1, 0.3, refined=True)
    for s in (0.52, 0.55, 0.583):
        dm.record(s, 0.62, PRECISE)
    dm.record(0.5996, 0.41, ROUGH)
    for s in (0.61, 0.63, 0.66):
        dm.record(s, 0.30, PRECISE)
    assert dm.average(0.52, 0.66) == pytest.approx((0.08 * 0.62 + 0.06 * 0.30) / 0.14)
    fast = DepthMap(0.0, 0.1, 0.3, refined=True)
    for s in (0.72, 0.75, 0.78):
        fast.record(s, 0.9, ROUGH)
    fast.record(0.85, 0.5, ROUGH)
    assert fast.average(0.7, 0.9) == pytest.approx((0.1 * 0.9 + 0.1 * 0.5) / 0.2)


def test_a_bin_only_a_neighbour_has_measured_is_measured_near_its_depth():
    """The last centimetres of a segment in a bin the neighbour has measured: the leg
    goes slowly near the neighbour's depth, not the whole way down as on a column
    nobody has measured."""
    cfg = PatrolConfig()
    dm = DepthMap(0.0, 0.1, cfg.min_depth_m, refined=True)
    dm.record(0.35, 0.5, PRECISE)
    dm.cross(0.35, 0.0)
    dm.learn(((4, 1.2),))
    assert dm.expected_depths(0.45) == (1.2,)
    assert dm.expected_depths(0.55) == ()  # nobody's
    patrol = Patrol(cfg, dm, x=0.43)
    patrol.motion, patrol.in_leg = Motion.UNDER, InLeg(entry_y=0.0, from_water=True)
    slow = [patrol._measuring(0.43, y, False) for y in (0.3, 0.6, 1.0, 1.15, 1.3)]
    assert slow == [False, False, False, True, False]
