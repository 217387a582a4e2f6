"""Unit tests of the pure simulator core: maps, PNG loading, kinematics, World."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from PIL import Image

from agent.phase import wrap_pi
from simworld.kinematics import (
    MAX_WHEEL_SPEED,
    WHEEL_BASE_M,
    limit_wheels,
    step_pose,
)
from simworld.maps import MapError, builtin_map, load_map, load_png
from simworld.world import World, start_poses

BLUE, WHITE, GREEN = (0, 0, 255), (255, 255, 255), (0, 255, 0)


# maps ---------------------------------------------------------------------------
def test_half_algae_patrol_depths() -> None:
    m = builtin_map("half-algae")
    assert (m.edge_lo, m.edge_hi) == (0.0, 6.0)
    for x in (0.05, 1.0, 2.95):
        assert m.patrol_depth(x) == pytest.approx(1.5)
    for x in (3.05, 4.5, 5.95):
        assert m.patrol_depth(x) == pytest.approx(0.3)
    bins = m.patrol_depth_bins(0.1)
    assert len(bins) == 60
    assert bins[:30] == pytest.approx([1.5] * 30)
    assert bins[30:] == pytest.approx([0.3] * 30)


def test_no_algae_and_sensing() -> None:
    m = builtin_map("no-algae")
    assert m.patrol_depth_bins() == pytest.approx([0.3] * 60)
    assert m.ice_at(1.0, 0.005) and not m.ice_at(1.0, -0.005)
    assert not m.ice_at(-0.1, 1.0) and not m.ice_at(6.1, 1.0)  # outside the grid
    assert not m.ice_at(1.0, -5.0)  # water below the grid
    assert m.edge_y(2.0) == 0.0
    assert m.y_bottom <= -2.5
    h = builtin_map("half-algae")
    assert h.algae_at(1.0, 1.49) and not h.algae_at(1.0, 1.51) and not h.algae_at(4.0, 0.1)
    assert not h.algae_at(1.0, -0.5)


def test_random_algae_range_and_seed() -> None:
    a = builtin_map("random-algae", seed=7).patrol_depth_bins()
    b = builtin_map("random-algae", seed=7).patrol_depth_bins()
    c = builtin_map("random-algae", seed=8).patrol_depth_bins()
    assert len(a) == 60 and a == b and a != c
    assert all(0.3 <= d <= 1.5 + 1e-9 for d in a)
    assert max(a) > 1.0  # really random, not all minimum
    assert load_map("random-algae", seed=7).patrol_depth_bins() == a


def _png(tmp_path, pixels: np.ndarray, name: str = "map.png"):
    path = tmp_path / name
    Image.fromarray(pixels.astype(np.uint8), "RGB").save(path)
    return path


def _sloped_image() -> np.ndarray:
    """10 columns by 60 rows at 0.05 m/px: the edge rises one pixel per column from
    the left; columns 0-3 hold 4 px (0.2 m) of algae above their edge; column 9 is
    water only. Image row 0 is the top."""
    h, w = 60, 10
    img = np.zeros((h, w, 3), dtype=np.uint8)
    img[:, :] = BLUE
    for col in range(9):
        edge_row_from_bottom = 45 + col  # 2.25 m of water below the lowest edge
        top = h - 1 - edge_row_from_bottom
        img[: top + 1, col] = WHITE
        if col < 4:
            img[top - 3 : top + 1, col] = GREEN
    return img


def test_png_sloped_edge_algae_and_scale(tmp_path) -> None:
    img = _sloped_image()
    m = load_png(_png(tmp_path, img), scale_m_per_px=0.05)
    assert m.edge_lo == 0.0 and m.edge_hi == pytest.approx(9 * 0.05)
    assert m.edge_y(0.01) == pytest.approx(0.0)
    assert m.edge_y(0.05 * 5 + 0.01) == pytest.approx(5 * 0.05)  # local edge rises
    assert m.patrol_depth(0.06) == pytest.approx(0.3)  # 0.2 m of algae < minimum
    assert m.algae_depth(0.06) == pytest.approx(0.2)
    assert m.algae_at(0.06, 0.05 + 0.1) and not m.algae_at(0.06, 0.05 + 0.22)
    assert m.ice_at(0.26, 0.26) and not m.ice_at(0.26, 0.24)
    assert not m.ice_at(0.47, 1.0)  # column 9 is water
    # same picture at twice the scale: everything doubles
    m2 = load_png(_png(tmp_path, img, "b.png"), scale_m_per_px=0.1)
    assert m2.edge_hi == pytest.approx(0.9) and m2.algae_depth(0.12) == pytest.approx(0.4)


def test_edge_y_bins_follow_a_sloped_edge(tmp_path) -> None:
    m = load_png(_png(tmp_path, _sloped_image()), scale_m_per_px=0.05)
    # two 0.05 m columns per 0.1 m bin, the edge one pixel higher in each; the last
    # bin holds column 8 only (column 9 is water)
    bins = m.edge_y_bins(0.1)
    assert bins == pytest.approx([0.025, 0.125, 0.225, 0.325, 0.4])
    assert len(bins) == len(m.patrol_depth_bins(0.1))
    assert m.edge_y_bins(0.05) == pytest.approx([0.05 * c for c in range(9)])
    assert builtin_map("half-algae").edge_y_bins() == [0.0] * 60


def test_png_deep_algae_sets_patrol_depth(tmp_path) -> None:
    img = np.zeros((80, 4, 3), dtype=np.uint8)
    img[:, :] = BLUE
    img[:40, :] = WHITE
    img[20:40, :2] = GREEN  # 20 px = 1.0 m of algae above the edge in columns 0-1
    img[39, 3] = (200, 230, 210)  # near-white counts as ice: column 3's edge stays at 0
    img[45, 2] = (40, 60, 200)  # near-blue counts as water
    m = load_png(_png(tmp_path, img))
    assert m.patrol_depth(0.01) == pytest.approx(1.0)
    assert m.patrol_depth(0.16) == pytest.approx(0.3)
    assert m.patrol_depth_bins(0.1) == pytest.approx([1.0, 0.3])
    assert m.edge_y(0.16) == 0.0 and m.edge_y(0.11) == 0.0


def test_png_refuses_garbage(tmp_path) -> None:
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"this is not an image")
    with pytest.raises(MapError, match="cannot read map image"):
        load_png(bad)
    with pytest.raises(MapError, match="cannot read map image"):
        load_map(str(tmp_path / "missing.png"))


def test_png_refuses_no_ice(tmp_path) -> None:
    img = np.zeros((50, 5, 3), dtype=np.uint8)
    img[:, :] = BLUE
    with pytest.raises(MapError, match="no ice pixel"):
        load_png(_png(tmp_path, img))


def test_png_refuses_too_little_water(tmp_path) -> None:
    img = np.zeros((60, 6, 3), dtype=np.uint8)
    img[:, :] = BLUE
    img[:30, :] = WHITE
    img[:36, 4] = WHITE  # column 4's edge is lowest: 24 px = 1.2 m of water below it
    with pytest.raises(MapError) as err:
        load_png(_png(tmp_path, img))
    text = str(err.value)
    assert "not enough water" in text and "column 4" in text and "row 35" in text
    assert "1.20 m" in text and "laser" in text
    with pytest.raises(MapError, match="not enough water"):
        load_map(str(_png(tmp_path, img, "again.png")))


def test_unknown_map_name() -> None:
    with pytest.raises(MapError, match="unknown map"):
        load_map("no-such-map")


# kinematics ---------------------------------------------------------------------
def test_wheel_limit_keeps_curvature() -> None:
    v, w = limit_wheels(1.0, 2.0)
    half = 0.5 * w * WHEEL_BASE_M
    assert max(abs(v - half), abs(v + half)) == pytest.approx(MAX_WHEEL_SPEED)
    assert w / v == pytest.approx(2.0)
    assert limit_wheels(0.2, 0.5) == (0.2, 0.5)  # within limits: untouched
    v, w = limit_wheels(0.0, 10.0)  # spin in place
    assert v == 0.0 and 0.5 * w * WHEEL_BASE_M == pytest.approx(MAX_WHEEL_SPEED)


@given(st.floats(-5, 5), st.floats(-20, 20))
def test_wheel_limit_property(v: float, omega: float) -> None:
    lv, lw = limit_wheels(v, omega)
    half = 0.5 * lw * WHEEL_BASE_M
    assert max(abs(lv - half), abs(lv + half)) <= MAX_WHEEL_SPEED + 1e-9
    assert lv * omega == pytest.approx(lw * v, abs=1e-9)  # same curvature


def test_straight_and_arc_integration() -> None:
    assert step_pose(1.0, 2.0, 0.0, 0.5, 0.0, 2.0) == pytest.approx((2.0, 2.0, 0.0))
    x, y, th = step_pose(0.0, 0.0, math.pi / 2, 0.3, 0.0, 1.0)
    assert (x, y, th) == pytest.approx((0.0, 0.3, math.pi / 2), abs=1e-12)
    # quarter circle of radius 1 from heading +x, turning left
    x, y, th = step_pose(0.0, 0.0, 0.0, math.pi / 2, math.pi / 2, 1.0)
    assert (x, y, th) == pytest.approx((1.0, 1.0, math.pi / 2))
    # half circle, turning right, radius 0.5
    x, y, th = step_pose(0.0, 0.0, 0.0, 0.5 * math.pi, -math.pi, 1.0)
    assert (x, y) == pytest.approx((0.0, -1.0), abs=1e-12)
    assert abs(wrap_pi(th - math.pi)) < 1e-12
    # many small steps equal one big step (exact arcs compose)
    pose = (0.3, -0.2, 0.4)
    for _ in range(100):
        pose = step_pose(*pose, 0.4, 0.7, 0.01)
    assert pose == pytest.approx(step_pose(0.3, -0.2, 0.4, 0.4, 0.7, 1.0))


@given(st.floats(-50, 50))
def test_wrap_pi_range(a: float) -> None:
    w = wrap_pi(a)
    assert -math.pi < w <= math.pi
    assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-9)


# world --------------------------------------------------------------------------
def _drive(world: World, ticks: int) -> list[tuple[float, ...]]:
    out = []
    for k in range(ticks):
        cmds = {i: (0.3, 0.2 * math.sin(0.1 * k + i)) for i in range(world.n)}
        world.step(cmds, 0.1)
        for i in range(world.n):
            r = world.sense(i)
            out.append(world.truth(i) + world.odometry_pose(i) + (r.odom_dist_m, r.ice))
    return out


def test_world_same_seed_same_run() -> None:
    m = builtin_map("half-algae")
    a = _drive(World(m, 3, seed=5, odom_noise=0.05), 200)
    b = _drive(World(m, 3, seed=5, odom_noise=0.05), 200)
    c = _drive(World(m, 3, seed=6, odom_noise=0.05), 200)
    assert a == b and a != c


def test_world_odometry_and_sensing() -> None:
    m = builtin_map("half-algae")
    w = World(m, 3, odom_noise=0.0)
    assert w.sense(0).odom_dist_m == 0.0
    for _ in range(20):  # 2 s at 0.5 m/s, straight up: from y = -1 to y = 0 under the ice
        w.step({0: (0.5, 0.0)}, 0.1)
    x, y, th = w.truth(0)
    assert y == pytest.approx(0.0, abs=1e-9) and th == pytest.approx(math.pi / 2)
    assert w.odometry_pose(0) == pytest.approx(w.truth(0))  # no noise: exact dead reckoning
    assert w.sense(0).odom_dist_m == pytest.approx(0.05)
    w.step({0: (0.5, 0.0)}, 0.1)
    assert w.sense(0).ice and w.sense(0).algae  # x = 0.05 is in the algae half
    assert w.truth(1)[1] == -1.0  # no command: robot 1 did not move
    noisy = World(m, 1, odom_noise=0.1)
    for _ in range(50):
        noisy.step({0: (0.3, 0.3)}, 0.1)
    assert noisy.odometry_pose(0) != pytest.approx(noisy.truth(0), abs=1e-6)


def test_world_odometry_turn_noise_apart_from_distance_noise() -> None:
    m = builtin_map("half-algae")
    gyro = World(m, 1, odom_noise=0.05, odom_turn_noise=0.0)  # wheels noisy, heading exact
    wheels = World(m, 1, odom_noise=0.0, odom_turn_noise=0.05)  # distance exact, turns noisy
    for _ in range(50):
        gyro.step({0: (0.3, 0.6)}, 0.1)
        wheels.step({0: (0.3, 0.6)}, 0.1)
    assert gyro.odometry_pose(0)[2] == pytest.approx(gyro.truth(0)[2], abs=1e-12)
    assert gyro.odometry_pose(0)[:2] != pytest.approx(gyro.truth(0)[:2], abs=1e-6)
    assert wheels.odometry_pose(0)[2] != pytest.approx(wheels.truth(0)[2], abs=1e-6)
    assert wheels.info()["odom_noise"] == 0.0 and wheels.info()["odom_turn_noise"] == 0.05
    assert World(m, 1, odom_noise=0.03).odom_turn_noise == 0.03  # one noise for both
    with pytest.raises(ValueError, match="noise"):
        World(m, 1, odom_turn_noise=-0.1)


def test_start_placement() -> None:
    m = builtin_map("no-algae")
    inphase = start_poses(m, 3, "in-phase")
    assert [p[0] for p in inphase] == pytest.approx([0.05, 2.05, 4.05])
    assert all(p[1] == -1.0 and p[2] == pytest.approx(math.pi / 2) for p in inphase)
    ahead = start_poses(m, 3, "ahead:1")
    assert [p[0] for p in ahead] == pytest.approx([0.05, 2.0 + 0.4 * 2.0, 4.05])
    w = World(m, 3, start="ahead:1")
    assert w.truth(1) == pytest.approx((2.8, -1.0, math.pi / 2))
    with pytest.raises(ValueError):
        start_poses(m, 3, "ahead:3")
    with pytest.raises(ValueError):
        start_poses(m, 3, "sideways")


def test_world_info_fields() -> None:
    from wire import WorldInfo, decode, encode

    w = World(builtin_map("half-algae"), 3)
    run = dict(map="half-algae", start="in-phase", robots=3, localization="truth", seed=1)
    info = WorldInfo(**run, duration_s=10.0, dt=0.1, **w.info())  # type: ignore[arg-type]
    assert decode(WorldInfo, encode(info)) == info
    assert info.robot_radius == 0.17 and info.min_depth == 0.3 and info.bin_m == 0.01
    assert len(info.patrol_depth) == 600  # the map's own 1 cm cells
    assert info.edge_y == [0.0] * 600  # the built-in maps' edge is straight at y = 0


def test_a_maps_bins_are_kept_and_a_caller_cannot_change_them():
    """The world tells its true depth and edge every 100 ticks: the bins are worked out
    once per width, the same as worked out afresh, and a caller's copy is its own."""
    gmap = load_map("half-algae", 0.05, 1)
    depth = gmap.patrol_depth_bins(0.1)
    edge = gmap.edge_y_bins(0.1)
    assert depth == gmap.patrol_depth_bins(0.1, gmap.algae_extent_m)
    assert len(depth) == len(edge) and max(depth) > min(depth)
    depth[0] = edge[0] = 99.0
    assert gmap.patrol_depth_bins(0.1)[0] != 99.0 and gmap.edge_y_bins(0.1)[0] != 99.0
    assert len(gmap.patrol_depth_bins(0.05)) == 2 * len(gmap.patrol_depth_bins(0.1))
    floe = load_map("floe:1,shape=round,size=2.5,algae=blooms", 0.05, 1)
    ring = floe.ring_patrol_depth_bins(300)
    ring[0] = 99.0
    again = floe.ring_patrol_depth_bins(300)
    assert again[0] != 99.0 and len(again) == 300
    assert again == load_map("floe:1,shape=round,size=2.5,algae=blooms", 0.05,
                             1).ring_patrol_depth_bins(300)
