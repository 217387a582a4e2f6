"""Maps that change during a run (issue 18): the time-varying map (pure), the agents'
depth map forgetting what is stale, the report's true depth in time and the rebalance
after each change, the recorder's judgement of a changed depth profile, and the CLI."""

from __future__ import annotations

import math
import random
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.depthmap import PRECISE, ROUGH, DepthMap
from recorder.writer import Recording, RunWriter
from report.measures import EdgeModel, TeamErrors, change_recovery
from simworld.change import ChangeError, ChangingMap, changing_map, frames, parse_changes
from simworld.maps import load_map
from simworld.world import World
from wire import Tick, WorldInfo, encode


def _half() -> ChangingMap:
    gmap = load_map("half-algae")
    change = changing_map(gmap, ["grow:0.5@60-660"])
    assert change is not None
    return change


# --- the spec -------------------------------------------------------------------------
def test_specs_parse_in_time_order() -> None:
    changes = parse_changes(["blend:procedural:7,algae=blooms@700-800", "recede:0.25@0-60",
                             "grow:0.5@60-660"])
    assert [str(c) for c in changes] == ["grow:-0.25@0-60", "grow:0.5@60-660",
                                         "blend:procedural:7,algae=blooms@700-800"]


@pytest.mark.parametrize("spec, says", [
    ("grow", "no kind"), ("shrink:0.5@1-2", "unknown kind 'shrink'"),
    ("grow:0.5", "no window"), ("grow:0.5@10", "is not T0-T1"),
    ("grow:0.5@20-10", "need 0 <= T0 < T1"), ("grow:half@1-2", "'half' is not a number"),
    ("recede:2@1-2", "not a fraction in [0, 1]"), ("grow:nan@1-2", "not a finite number"),
    ("blend:@1-2", "names no map"),
])
def test_bad_specs_are_refused_saying_what_is_wrong(spec: str, says: str) -> None:
    with pytest.raises(ChangeError, match=None) as err:
        parse_changes([spec])
    assert says in str(err.value) and repr(spec) in str(err.value)


def test_overlapping_windows_are_refused() -> None:
    with pytest.raises(ChangeError, match="overlaps"):
        parse_changes(["grow:0.5@0-100", "recede:0.5@50-150"])


# --- the map in time -----------------------------------------------------------------
@settings(max_examples=300, deadline=None)
@given(x=st.floats(-0.5, 6.5), y=st.floats(-3.5, 3.5), t=st.floats(0.0, 60.0))
def test_before_a_change_the_map_is_the_runs_map(x: float, y: float, t: float) -> None:
    change = _half()
    assert change.algae_at(x, y, change.extent_cells(t)) == change.base.algae_at(x, y)


def test_algae_grows_by_half_its_depth_over_the_window() -> None:
    change = _half()
    depth = {t: change.patrol_depth_bins(t, 0.1) for t in (0.0, 60.0, 360.0, 660.0, 900.0)}
    assert depth[0.0] == depth[60.0] and depth[0.0][:30] == [1.5] * 30
    assert depth[360.0][:30] == pytest.approx([1.88] * 30)  # half way, to whole cells
    assert depth[660.0][:30] == depth[900.0][:30] == pytest.approx([2.25] * 30)
    assert depth[900.0][30:] == [0.3] * 30  # no algae grows none
    series = [change.patrol_depth_bins(float(t), 0.1)[0] for t in range(60, 661, 20)]
    assert series == sorted(series)  # it only grows


def test_the_world_senses_the_map_of_its_time() -> None:
    change = _half()
    world = World(change.base, 1, change=change)
    y = 1.8 + 0.005  # above 1.5 m of algae, below 2.25 m
    assert not change.base.algae_at(1.0, y)
    world._x[0], world._y[0] = 1.0, y  # the robot stands still there
    seen = []
    for _ in range(7000):
        seen.append(world.sense(0).algae)
        world.step({}, 0.1)
    first = seen.index(True)
    assert 3000 < first < 6600 and all(seen[first:])  # grown over it, and stays
    assert type(world.sense(0).algae) is bool  # a message field, not numpy's


def test_a_recession_leaves_a_patchy_column_its_own_algae_below() -> None:
    gmap = load_map("half-algae")
    algae = gmap.algae.copy()
    col, edge = 100, int(gmap.edge_rows[100])
    algae[edge + 50:edge + 100, col] = False  # a gap: algae 0-0.5 m and 1-1.5 m
    from simworld.maps import GridMap

    patchy = GridMap(gmap.ice, algae, gmap.cell_m, "patchy")
    change = ChangingMap(patchy, parse_changes(["recede:0.5@0-10"]))
    extent = change.algae_m(10.0)  # 1.5 m recedes to 0.75 m: the patch below is 0.5 m
    assert extent[col] == pytest.approx(0.5) and extent[col + 1] == pytest.approx(0.75)
    ext = change.extent_cells(10.0)
    x = (col + 0.5) * gmap.cell_m
    assert change.algae_at(x, 0.45, ext) and not change.algae_at(x, 0.6, ext)


def test_a_blend_ends_on_the_other_maps_algae() -> None:
    base = load_map("procedural:7,length=6,algae=steps")
    other = "procedural:7,length=6,algae=blooms"
    change = changing_map(base, [f"blend:{other}@10-20"])
    assert change is not None
    assert change.patrol_depth_bins(20.0, 0.1) == pytest.approx(
        load_map(other).patrol_depth_bins(0.1), abs=1e-9)
    assert change.patrol_depth_bins(5.0, 0.1) == base.patrol_depth_bins(0.1)


def test_a_blend_with_other_ice_is_refused() -> None:
    base = load_map("procedural:7,length=6,algae=steps")
    with pytest.raises(ChangeError, match="its ice differs"):
        changing_map(base, ["blend:half-algae@10-20"])


def test_frames_come_every_second_of_a_window_and_at_its_ends() -> None:
    change = changing_map(load_map("half-algae"), ["grow:0.5@10.25-13"])
    assert change is not None
    times, depths = frames(change, 200, 0.1, 0.01)
    assert times == pytest.approx([0.0, 10.3, 11.0, 12.0, 13.0])  # 10.25 s is tick 103
    assert len(depths[0]) == 600 and depths[-1][0] == pytest.approx(1.5 * 1.5)


# --- the report's true depth in time ----------------------------------------------
def test_true_workload_follows_the_frames_and_a_static_edge_is_unchanged() -> None:
    static = EdgeModel(0.0, 2.0, 1.0, (1.0, 1.0))
    moving = EdgeModel(0.0, 2.0, 1.0, (1.0, 1.0), frame_t=(0.0, 10.0, 20.0),
                       frames=((1.0, 1.0), (1.0, 1.0), (2.0, 1.0)), change_windows=(10.0, 20.0))
    t = np.array([0.0, 5.0, 10.0, 15.0, 20.0, 30.0])
    lo, hi = np.zeros(t.size), np.full(t.size, 2.0)
    assert np.array_equal(static.workload(lo, hi, t), static.workload(lo, hi))
    assert moving.workload(lo, hi, t) == pytest.approx([2.0, 2.0, 2.0, 2.5, 3.0, 3.0])
    assert moving.total_workload_at(t) == pytest.approx([2.0, 2.0, 2.0, 2.5, 3.0, 3.0])
    assert moving.changes == [(10.0, 20.0)]


def test_the_rebalance_is_timed_from_the_changes_end() -> None:
    t = np.arange(0.0, 100.0, 0.1)
    edge = EdgeModel(0.0, 2.0, 1.0, (1.0, 1.0), frame_t=(0.0,), frames=((1.0, 1.0),),
                     change_windows=(10.0, 20.0))
    error = np.where((t > 10.0) & (t < 50.0), 0.5, 0.0)[None, :]  # back at 50 s
    errors = TeamErrors(t=t, pairs=[(0, 1)], phase=error, phase_path=error, workload=error,
                        workload_agents=error, phase_agents=error, ids=[0, 1],
                        live=np.ones((2, t.size), dtype=bool))
    (row,) = change_recovery(errors, edge, np.full((2, t.size), 15.0), smooth_s=0.0)
    assert row["back_s"] == pytest.approx(30.0, abs=0.11)
    assert row["back_cycles"] == pytest.approx(2.0, abs=0.01)
    assert row["settled_s"] == pytest.approx(30.0, abs=0.11)
    assert row["band_m2"] == pytest.approx(0.005) and row["peak_rel"] == pytest.approx(0.5)


# --- the agents forget what is stale --------------------------------------------------
def test_an_old_precise_sample_does_not_outlive_a_change() -> None:
    dm = DepthMap(0.0, 0.1, 0.3)
    for s in (0.03, 0.05, 0.07):
        dm.record(s, 1.5, PRECISE)
    dm.record(0.072, 2.0, ROUGH)  # the algae grew: crossed at full speed, unexpected
    assert not dm.changing and dm.depths[0] == pytest.approx(1.5)  # one may stray
    dm.record(0.041, 2.05, ROUGH)  # a second says so too: the bin forgets the old
    assert dm.changing and dm.depths[0] == pytest.approx(2.05)
    assert [p[1] for p in dm.points[0]] == pytest.approx([2.0, 2.05])
    dm.record(0.21, 0.3, PRECISE)  # elsewhere, so the profile has a fresh sample
    for _ in range(30):  # a cycle of 2 s later, the bin's samples are stale
        dm.tick(0.1, 2.0)
    dm.record(0.215, 0.3, PRECISE)
    dm.tick(0.1, 2.0)
    assert 0 not in dm.points and dm.average(0.0, 0.1) == pytest.approx(0.3)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(0.02, 0.98), st.floats(-0.04, 0.04), st.booleans()),
                min_size=5, max_size=80))
def test_a_static_profile_never_looks_changed(samples: list[tuple[float, float, bool]]
                                              ) -> None:
    # samples of a step profile (1.5 m, then 0.3 m past 0.5 m) with ROUGH noise, the
    # step at a bin's side, and a slope of 3 (a bloom's flank) past 0.7 m: the map never
    # takes either for a change
    dm = DepthMap(0.0, 0.1, 0.3)
    for s, noise, precise in samples:
        depth = 1.5 if s < 0.5 else 0.3 if s < 0.7 else 0.3 + 3.0 * (s - 0.7)
        dm.record(s, depth + noise, PRECISE if precise else ROUGH)
        dm.tick(0.1, 1.0)
    assert not dm.changing and dm.contradicted is None


# --- the recorder judges a changed depth profile ---------------------------------------
def _info(depth: list[float], *, windows: list[float], depth_t: float = 0.0,
          edge_hi: float = 2.0) -> bytes:
    return encode(WorldInfo(
        map="m", start="in-phase", robots=1, localization="truth", seed=1, duration_s=100.0,
        dt=0.1, edge_lo=0.0, edge_hi=edge_hi, bin_m=1.0, patrol_depth=depth,
        robot_radius=0.17, min_depth=0.3, margin_out=0.3,
        change="grow:1@10-20" if windows else "", change_windows=windows, depth_t=depth_t))


def test_the_recorder_takes_a_changed_depth_only_on_a_map_declared_to_change(
        tmp_path: Path) -> None:
    for windows in ([10.0, 20.0], []):
        writer = RunWriter(tmp_path / f"run{len(windows)}.mcap")
        rec = Recording(writer)
        rec.handle("world/info", _info([1.0, 1.0], windows=windows), 1)
        for k in range(120):
            rec.handle("world/tick", encode(Tick(t=k * 0.1, k=k, live=[0])), 2 + k)
        before = writer.messages if hasattr(writer, "messages") else None
        rec.handle("world/info", _info([1.5, 1.0], windows=windows, depth_t=12.0), 200)
        rec.handle("world/info", _info([1.2, 1.0], windows=windows, depth_t=11.0), 201)
        rec.handle("world/info", _info([1.6, 1.0], windows=windows, depth_t=40.0), 202)
        rec.handle("world/info", _info([1.0, 1.0], windows=windows, edge_hi=3.0), 203)
        writer.close()
        del before
        from report.load import load_run

        run = load_run(tmp_path / f"run{len(windows)}.mcap")
        if windows:  # the frame of 12 s taken; back in time, out of a window, refused
            assert run.depth_frames == [(0.0, [1.0, 1.0]), (12.0, [1.5, 1.0])]
            assert sum(run.rejected.values()) == 3
        else:  # a static map: every changed profile refused
            assert run.depth_frames == [] and run.info["patrol_depth"] == [1.0, 1.0]
            assert sum(run.rejected.values()) == 4


# --- the CLI ------------------------------------------------------------------------------
def btrack(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "btrack", *args], capture_output=True,
                          text=True, timeout=60)


@pytest.mark.parametrize("extra, says", [
    (["--change", "grow:0.5@60"], "bad --change 'grow:0.5@60': window '60' is not T0-T1"),
    (["--change", "grow:0.5@0-100", "--change", "grow:0.2@50-60"], "overlaps"),
    (["--change", "blend:no-such-map@1-2"], "--change blend:no-such-map: unknown map"),
    (["--change", "grow:0.5@1000-1100", "--duration", "100"], "after the run's end"),
    (["--change", "grow:0.5@1-2", "--sensors", "lab"], "the lab sensors read a static map"),
    (["--change", "grow:0.5@1-2", "--map", "floe:1", "--engine", "inprocess"],
     "a closed edge (a ring round a floe) does not change yet"),
])
def test_btrack_sim_refuses_a_bad_change_saying_what_is_wrong(tmp_path: Path,
                                                               extra: list[str],
                                                               says: str) -> None:
    done = btrack("sim", "--out", str(tmp_path / "out"), "--quiet", *extra)
    assert done.returncode == 2, done.stdout + done.stderr
    assert says in done.stdout + done.stderr and "Traceback" not in done.stderr


def test_a_change_that_ends_after_the_run_is_fine_as_far_as_it_goes() -> None:
    change = changing_map(load_map("half-algae"), ["grow:1@0-1000"])
    assert change is not None
    assert change.patrol_depth_bins(100.0, 0.1)[0] == pytest.approx(1.65)
    assert math.isfinite(change.changes[0].t1)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.515, 0.585))
def test_a_step_inside_a_column_never_looks_changed(seed: int, step: float) -> None:
    # a step of 0.83 m inside a column (not at a bin's side), sampled leg after leg a
    # few millimetres either side of it, as sweeps at new offsets do: samples a
    # centimetre apart across it disagree by far more than a change's STALE_M, and the
    # map must still not take the static profile for a changing one
    rng = random.Random(seed)
    dm = DepthMap(0.0, 0.1, 0.3)
    for _ in range(200):
        s = step + rng.uniform(-0.02, 0.02)
        depth = 0.3 if s < step else 1.13
        dm.record(s, depth + rng.uniform(-0.004, 0.004),
                  PRECISE if rng.random() < 0.8 else ROUGH)
        dm.tick(0.1, 60.0)  # a leg a tick, all within the team's cycle
    assert not dm.changing and dm.changed_t == 0.0  # nor was it, for a while
