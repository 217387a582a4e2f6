"""Closed edges from pixels (simworld.contour), their frame (agent.edgeframe) and the
floe family (simworld.floes)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.edgeframe import ClosedEdge
from simworld.contour import MIN_BEND_RADIUS_M, normal_depths
from simworld.floes import FloeSpec, floe_map
from simworld.maps import GridMap, MapError, load_map, load_png, write_png

CELL = 0.01
RADIUS = 1.5
ROOM = 2.2  # water round the disk: the start line's and the laser's room and more


def disk(radius: float = RADIUS, cell: float = CELL, room: float = ROOM,
         centre: tuple[float, float] = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """A grid whose ice is a disk, its cells' centres' x and y (row 0 lowest)."""
    half = radius + room
    n = int(round(2 * half / cell))
    c = (np.arange(n) + 0.5) * cell - half
    x, y = np.meshgrid(c, c)
    return np.hypot(x - centre[0], y - centre[1]) < radius, np.stack([x, y])


@pytest.fixture(scope="module")
def disk_map() -> GridMap:
    ice, _ = disk()
    return GridMap(ice=ice, algae=np.zeros_like(ice), cell_m=CELL, name="disk", closed=True)


def test_a_disk_s_contour_is_within_a_cell_of_the_circle(disk_map: GridMap) -> None:
    edge = disk_map.closed_edge
    pts = np.asarray(edge.points)
    # the grid's corner is at x = 0; the disk's centre at the middle of the grid, and
    # y = 0 is the lowest ice pixel's bottom
    cx = 0.5 * disk_map.width_m
    cy = disk_map.y_bottom + 0.5 * disk_map.rows * CELL
    r = np.hypot(pts[:, 0] - cx, pts[:, 1] - cy)
    assert np.abs(r - RADIUS).max() <= CELL
    assert edge.length == pytest.approx(2 * math.pi * RADIUS, rel=0.005)
    assert disk_map.edge_lo == 0.0 and disk_map.edge_hi == edge.length
    # counterclockwise, the ice on its left: a little in is ice, a little out water
    for s in np.linspace(0, edge.length, 37)[:-1]:
        assert disk_map.ice_at(*edge.at(s, 3 * CELL))
        assert not disk_map.ice_at(*edge.at(s, -3 * CELL))
        # a 1 cm staircase wobbles a few mm over a metre, which no smoothing that keeps
        # the shape removes: a tenth of the bend's curvature
        assert edge.curvature_at(s) == pytest.approx(1 / RADIUS, abs=0.15)


@settings(max_examples=60, deadline=None)
@given(st.floats(0, 1), st.floats(-1.2, 1.2))
def test_the_frame_maps_back_what_it_maps(frac: float, d: float) -> None:
    edge = _disk_edge()
    s = frac * edge.length
    x, y = edge.at(s, d)
    s2, d2 = edge.project(x, y)
    assert d2 == pytest.approx(d, abs=1e-6)
    gap = (s2 - s + 0.5 * edge.length) % edge.length - 0.5 * edge.length
    assert abs(gap) < 1e-6
    # from a hint a little off, the walk finds the same point
    s3, _ = edge.project(x, y, hint=edge.wrap(s + 0.3))
    assert abs((s3 - s + 0.5 * edge.length) % edge.length - 0.5 * edge.length) < 1e-6


_EDGE: list[ClosedEdge] = []


def _disk_edge() -> ClosedEdge:
    if not _EDGE:
        ice, _ = disk()
        _EDGE.append(GridMap(ice=ice, algae=np.zeros_like(ice), cell_m=CELL,
                             closed=True).closed_edge)
    return _EDGE[0]


def test_a_leg_along_the_normal_is_straight_in_the_world() -> None:
    edge = _disk_edge()
    s, d = 1.0, 0.4
    assert edge.world_omega(0.5, 0.0, s, d, math.pi / 2) == pytest.approx(0.0, abs=1e-12)
    # along the edge, following it needs the edge's own turn, faster the deeper in
    on_edge = edge.world_omega(0.5, 0.0, s, 0.0, 0.0)
    deeper = edge.world_omega(0.5, 0.0, s, 0.5, 0.0)
    assert on_edge == pytest.approx(0.5 / RADIUS, rel=0.1)
    assert deeper == pytest.approx(0.5 / (RADIUS - 0.5), rel=0.1)


def test_a_png_island_is_a_closed_edge_and_round_trips(disk_map: GridMap, tmp_path) -> None:
    path = tmp_path / "island.png"
    write_png(disk_map, path)
    back = load_png(path, CELL)  # no ice on the border: closed without asking
    assert back.closed
    assert back.closed_edge.length == pytest.approx(disk_map.closed_edge.length, abs=1e-9)
    forced = load_map(f"closed:{path}", CELL)
    assert forced.closed_edge.n == disk_map.closed_edge.n


def test_refused_an_island_on_the_border(tmp_path) -> None:
    ice, _ = disk()
    ice[300:310, 0] = True  # a spit of ice on the left border, rows 300-309 from the bottom
    with pytest.raises(MapError, match=r"touches the image's border at pixel \(column 0, row"):
        GridMap(ice=ice, algae=np.zeros_like(ice), cell_m=CELL, closed=True)
    gmap = GridMap(ice=ice, algae=np.zeros_like(ice), cell_m=CELL)
    path = tmp_path / "spit.png"
    write_png(gmap, path)
    assert not load_png(path, CELL).closed  # ice on the border: an open edge, as before
    rows = ice.shape[0]
    with pytest.raises(MapError, match=rf"column 0, row {rows - 1 - 300} from the top"):
        load_map(f"closed:{path}", CELL)


def test_refused_two_islands_with_the_second_s_pixel() -> None:
    ice, _ = disk()
    ice[20:40, 30:50] = True  # a small square island in the lower left corner
    rows = ice.shape[0]
    with pytest.raises(MapError, match=rf"2 islands.*\(400 pixels\).*column 30, row "
                                       rf"{rows - 1 - 20} from the top"):
        GridMap(ice=ice, algae=np.zeros_like(ice), cell_m=CELL, closed=True)


def test_refused_a_hole_with_its_pixel() -> None:
    ice, _ = disk()
    mid = ice.shape[0] // 2
    ice[mid:mid + 5, mid:mid + 5] = False  # a pond in the floe
    rows = ice.shape[0]
    with pytest.raises(MapError, match=rf"hole .* at pixel \(column {mid}, row "
                                       rf"{rows - 1 - mid} from the top\)"):
        GridMap(ice=ice, algae=np.zeros_like(ice), cell_m=CELL, closed=True)


def test_refused_no_ice_and_a_bend_too_tight() -> None:
    ice, _ = disk()
    with pytest.raises(MapError, match="no ice"):
        GridMap(ice=ice & False, algae=np.zeros_like(ice), cell_m=CELL, closed=True)
    small, _ = disk(radius=0.6 * MIN_BEND_RADIUS_M, room=2.1)
    with pytest.raises(MapError, match=r"turns too tightly near pixel .* a bend of radius 0\.[56]"):
        GridMap(ice=small, algae=np.zeros_like(small), cell_m=CELL, closed=True)


def test_refused_an_island_too_near_the_border(tmp_path) -> None:
    ice, _ = disk(room=1.0)
    gmap = GridMap(ice=ice, algae=np.zeros_like(ice), cell_m=CELL, closed=True)
    path = tmp_path / "tight.png"
    write_png(gmap, path)
    with pytest.raises(MapError, match=r"not enough water round the island.*1\.0.* need 2\.0"):
        load_png(path, CELL)


def test_the_algae_s_depth_is_measured_along_the_inward_normal() -> None:
    ice, (x, y) = disk()
    depth = np.where(x > 0, 0.4, 0.2)  # deeper on the right half
    algae = ice & (RADIUS - np.hypot(x, y) < depth)
    gmap = GridMap(ice=ice, algae=algae, cell_m=CELL, closed=True)
    edge = gmap.closed_edge
    bins = 60
    got = normal_depths(edge, gmap.ice, gmap.algae, CELL, gmap.y_bottom, bins, 3.0)
    centres = (np.arange(bins) + 0.5) * edge.length / bins
    cx = 0.5 * gmap.width_m
    for s, d in zip(centres, got, strict=True):
        px, _ = edge.point(float(s))
        if abs(px - cx) > 0.2:  # away from the step between the halves
            assert d == pytest.approx(0.4 if px > cx else 0.2, abs=1.5 * CELL)
    patrol = gmap.ring_patrol_depth_bins(bins)
    assert min(patrol) == pytest.approx(0.3)  # the minimum depth where the algae is less


def test_floe_specs_name_and_refuse() -> None:
    spec = FloeSpec.parse("floe:7,shape=bay,size=3")
    assert FloeSpec.parse(spec.name()) == spec
    assert spec.shape == "bay" and spec.size_m == 3.0
    assert FloeSpec.from_seed(7, shape="bay").algae == spec.algae  # the override alone
    with pytest.raises(MapError, match="size must be in"):
        FloeSpec.parse("floe:7,size=1")
    with pytest.raises(MapError, match="shape must be one of"):
        FloeSpec.parse("floe:7,shape=square")
    with pytest.raises(MapError, match="bad field"):
        FloeSpec.parse("floe:7,colour=red")


@pytest.mark.parametrize("shape", ["round", "elongated", "bay"])
def test_every_floe_shape_builds_a_ring_the_robots_can_patrol(shape: str) -> None:
    gmap = floe_map(f"floe:1,shape={shape},size=2.5,algae=blooms")
    edge = gmap.closed_edge
    assert max(abs(k) for k in edge.curvature) <= 1 / MIN_BEND_RADIUS_M
    depths = gmap.ring_patrol_depth_bins(200)
    assert 0.3 <= min(depths) and max(depths) > 0.4  # algae deeper than the minimum
    if shape == "bay":
        assert min(edge.curvature) < -0.1  # a real bay: the edge bends away from the ice
    gmap.check_ring_room()


_BAY: list[ClosedEdge] = []


@settings(max_examples=60, deadline=None)
@given(st.floats(0, 1), st.floats(-0.9, 0.7), st.floats(-0.2, 0.2))
def test_the_frame_round_a_bay_maps_back_and_walks_from_a_hint(frac: float, d: float,
                                                               off: float) -> None:
    """Round a floe with a bay (concave and convex bends), from the start line out to
    the deepest legs in: a point's (s, d) is where the frame put it, found from a hint
    up to 0.2 m of s off (a robot's last foot)."""
    if not _BAY:
        _BAY.append(floe_map("floe:1,shape=bay,size=2.5,algae=none").closed_edge)
    edge = _BAY[0]
    s = frac * edge.length
    x, y = edge.at(s, d)
    s2, d2 = edge.project(x, y, hint=edge.wrap(s + off))
    assert d2 == pytest.approx(d, abs=1e-6)
    assert abs((s2 - s + 0.5 * edge.length) % edge.length - 0.5 * edge.length) < 1e-6
