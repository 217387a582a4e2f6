"""Ice and algae maps: a grid of cells, the built-in scenarios and the PNG loader.

Coordinates are metres: x along the edge (column 0 starts at x = 0), y across it,
growing upward into the ice; y = 0 is the lowest edge of the whole map. Row 0 of
the grid is the lowest (most negative y) row. A cell is ice if it is not water;
algae cells are under ice, so they are ice cells too.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from agent.edgeframe import ClosedEdge
from simworld.contour import ContourError, closed_edge, normal_depths

MIN_DEPTH_M = 0.3  # patrol depth where there is no (or little) algae
ROBOT_ROOM_M = 1.0  # robots start this far below the lowest edge
LASER_ROOM_M = 1.0  # the laser sits this far below the robots
BUILTIN_CELL_M = 0.01
BUILTIN_EDGE_M = 6.0
BUILTIN_ICE_M = 3.0
BUILTIN_WATER_M = 3.0
BUILTIN_NAMES = ("no-algae", "half-algae", "random-algae")

WATER_RGB = (0, 0, 255)
ICE_RGB = (255, 255, 255)
ALGAE_RGB = (0, 255, 0)


class MapError(ValueError):
    """A map that cannot be used, with the reason in the message."""


@dataclass(frozen=True, eq=False)
class GridMap:
    """Boolean ``ice[row, col]`` and ``algae[row, col]`` grids of square cells."""

    ice: np.ndarray
    algae: np.ndarray
    cell_m: float
    name: str = "map"
    min_depth: float = MIN_DEPTH_M
    # The ice is an island and its edge closed (a ring of robots patrols its contour):
    # traced from the grid in __post_init__, refused if it is not one island.
    closed: bool = False
    # derived per column, filled in __post_init__
    _edge_row: np.ndarray = field(init=False, repr=False)  # lowest non-water row, -1 if none
    _algae_m: np.ndarray = field(init=False, repr=False)  # algae extent above the local edge
    _y0: float = field(init=False, repr=False)  # y of the bottom of row 0
    _closed_edge: ClosedEdge | None = field(init=False, repr=False, default=None)
    # the bins of patrol_depth_bins, edge_y_bins and ring_patrol_depth_bins by their
    # arguments (``_kept``): the map does not change, and the world tells them every
    # INFO_EVERY_TICKS (about 75 ms on a 30 m edge's cells, 0.1 s round a floe)
    _bins: dict[tuple[object, ...], tuple[float, ...]] = field(
        init=False, repr=False, default_factory=dict)

    def __post_init__(self) -> None:
        ice = np.asarray(self.ice, dtype=bool)
        algae = np.asarray(self.algae, dtype=bool) & ice
        if ice.ndim != 2 or ice.shape != algae.shape:
            raise MapError("ice and algae grids must be 2-D and of the same shape")
        if not ice.any():
            raise MapError("the map has no ice")
        rows = ice.shape[0]
        has_ice = ice.any(axis=0)
        edge_row = np.where(has_ice, ice.argmax(axis=0), -1)
        # topmost algae row per column (rows counted from the bottom)
        has_algae = algae.any(axis=0)
        top_algae = rows - 1 - algae[::-1].argmax(axis=0)
        algae_m = np.where(has_algae, (top_algae + 1 - edge_row) * self.cell_m, 0.0)
        object.__setattr__(self, "ice", ice)
        object.__setattr__(self, "algae", algae)
        object.__setattr__(self, "_edge_row", edge_row)
        object.__setattr__(self, "_algae_m", np.maximum(algae_m, 0.0))
        object.__setattr__(self, "_y0", -float(edge_row[has_ice].min()) * self.cell_m)
        if self.closed:
            try:
                edge = closed_edge(ice, self.cell_m, self._y0, f"map {self.name}")
            except ContourError as exc:
                raise MapError(str(exc)) from None
            object.__setattr__(self, "_closed_edge", edge)

    @property
    def closed_edge(self) -> ClosedEdge:
        """The island's contour, s counterclockwise from its first vertex (closed maps)."""
        if self._closed_edge is None:
            raise MapError(f"map {self.name} has an open edge, not a closed one")
        return self._closed_edge

    def ring_patrol_depth_bins(self, bins: int, max_depth_m: float = 3.0) -> list[float]:
        """True patrol depth per bin of ``bins`` equal bins of the closed contour from
        s = 0: max(min_depth, the algae's depth along the inward normal)."""
        return self._kept(("ring", bins, max_depth_m), lambda: [
            round(float(max(self.min_depth, d)), 9)
            for d in normal_depths(self.closed_edge, self.ice, self.algae, self.cell_m,
                                   self._y0, bins, max_depth_m)])

    def _kept(self, key: tuple[object, ...], make: Callable[[], list[float]]) -> list[float]:
        """``make()``'s bins, worked out once for ``key``; a copy of them each time."""
        if key not in self._bins:
            self._bins[key] = tuple(make())
        return list(self._bins[key])

    def check_ring_room(self, where: str = "") -> None:
        """Refuse an island without ROBOT_ROOM_M + LASER_ROOM_M of water between it and
        the map's border, the robots' start line and the laser's room."""
        need = ROBOT_ROOM_M + LASER_ROOM_M
        rows, cols = np.nonzero(self.ice)
        gaps = {
            "left": (cols.min(), (int(rows[cols.argmin()]), int(cols.min()))),
            "right": (self.cols - 1 - cols.max(), (int(rows[cols.argmax()]), int(cols.max()))),
            "bottom": (rows.min(), (int(rows.min()), int(cols[rows.argmin()]))),
            "top": (self.rows - 1 - rows.max(), (int(rows.max()), int(cols[rows.argmax()]))),
        }
        side, (gap, (row, col)) = min(gaps.items(), key=lambda kv: kv[1][0])
        if gap * self.cell_m + 1e-9 < need:
            raise MapError(
                f"not enough water round the island{where}: at pixel (column {col}, row"
                f" {self.rows - 1 - row} from the top) it is {gap * self.cell_m:.2f} m from"
                f" the map's {side} side; need {need:.1f} m ({ROBOT_ROOM_M:.0f} m to the"
                f" robots' start line and {LASER_ROOM_M:.0f} m more)")

    # geometry --------------------------------------------------------------
    @property
    def rows(self) -> int:
        return int(self.ice.shape[0])

    @property
    def cols(self) -> int:
        return int(self.ice.shape[1])

    @property
    def y_bottom(self) -> float:
        """y of the map's lower border (the deepest water)."""
        return self._y0

    @property
    def y_top(self) -> float:
        return self._y0 + self.rows * self.cell_m

    @property
    def width_m(self) -> float:
        return self.cols * self.cell_m

    @cached_property
    def edge_lo(self) -> float:
        """s_0: the left side of the leftmost column holding ice (0 on a closed edge)."""
        if self._closed_edge is not None:
            return 0.0
        cols = np.flatnonzero(self._edge_row >= 0)
        return float(cols[0]) * self.cell_m

    @cached_property
    def edge_hi(self) -> float:
        """s_n: the right side of the rightmost column holding ice (the contour's length
        on a closed edge)."""
        if self._closed_edge is not None:
            return self._closed_edge.length
        cols = np.flatnonzero(self._edge_row >= 0)
        return float(cols[-1] + 1) * self.cell_m

    def _col(self, x: float) -> int:
        return math.floor(x / self.cell_m)

    @property
    def edge_rows(self) -> np.ndarray:
        """Per column, the lowest non-water row (-1 in a column without ice)."""
        return self._edge_row

    @property
    def algae_extent_m(self) -> np.ndarray:
        """Per column, the algae's extent above the local edge, m (0 if none)."""
        return self._algae_m

    def cell_of(self, x: float, y: float) -> tuple[int, int] | None:
        """The (row, column) of the cell holding (x, y); None off the grid."""
        return self._cell(x, y)

    def _cell(self, x: float, y: float) -> tuple[int, int] | None:
        col = math.floor(x / self.cell_m)
        row = math.floor((y - self._y0) / self.cell_m)
        if 0 <= col < self.ice.shape[1] and 0 <= row < self.ice.shape[0]:
            return row, col
        return None

    # sensing ---------------------------------------------------------------
    def ice_at(self, x: float, y: float) -> bool:
        cell = self._cell(x, y)
        return cell is not None and bool(self.ice[cell])

    def algae_at(self, x: float, y: float) -> bool:
        cell = self._cell(x, y)
        return cell is not None and bool(self.algae[cell])

    def edge_y(self, x: float) -> float:
        """The local edge at x: bottom of the lowest non-water cell of that column.
        Outside the columns holding ice, the lowest edge (y = 0)."""
        col = self._col(x)
        if 0 <= col < self.cols and self._edge_row[col] >= 0:
            return self._y0 + float(self._edge_row[col]) * self.cell_m
        return 0.0

    def algae_depth(self, x: float) -> float:
        """Algae extent at x, measured from the local edge (0 if none)."""
        col = self._col(x)
        if 0 <= col < self.cols:
            return float(self._algae_m[col])
        return 0.0

    def patrol_depth(self, x: float) -> float:
        """max(min_depth, algae extent at x) under the ice."""
        return max(self.min_depth, self.algae_depth(x))

    def patrol_depth_bins(self, bin_m: float = 0.1, algae_m: np.ndarray | None = None
                          ) -> list[float]:
        """True patrol depth per bin of width ``bin_m`` over [edge_lo, edge_hi]: the
        mean over the cell columns whose centres fall in the bin. ``algae_m``: the
        algae's extent per column to take instead of the map's own (a map that
        changes, ``simworld.change``)."""
        if algae_m is None:
            return self._kept(("depth", bin_m),
                              lambda: self.patrol_depth_bins(bin_m, self._algae_m))
        lo, hi = self.edge_lo, self.edge_hi
        n_bins = max(1, math.ceil((hi - lo) / bin_m - 1e-9))
        extent = algae_m
        depths = np.maximum(extent, self.min_depth)
        centres = (np.arange(self.cols) + 0.5) * self.cell_m
        out: list[float] = []
        for b in range(n_bins):
            a, z = lo + b * bin_m, min(hi, lo + (b + 1) * bin_m)
            sel = (centres >= a) & (centres < z)
            if sel.any():
                out.append(round(float(depths[sel].mean()), 9))
            else:  # bins finer than the cells: the cell under the bin's centre
                col = self._col(0.5 * (a + z))
                at = float(extent[col]) if 0 <= col < self.cols else 0.0
                out.append(max(self.min_depth, at))
        return out

    def edge_y_bins(self, bin_m: float = 0.1) -> list[float]:
        """The local edge's y per bin of width ``bin_m`` over [edge_lo, edge_hi] (the bins
        of ``patrol_depth_bins``): the mean over the cell columns holding ice whose
        centres fall in the bin."""
        return self._kept(("edge", bin_m), lambda: self._edge_y_bins(bin_m))

    def _edge_y_bins(self, bin_m: float) -> list[float]:
        lo, hi = self.edge_lo, self.edge_hi
        n_bins = max(1, math.ceil((hi - lo) / bin_m - 1e-9))
        has_ice = self._edge_row >= 0
        edge = self._y0 + self._edge_row * self.cell_m
        centres = (np.arange(self.cols) + 0.5) * self.cell_m
        out: list[float] = []
        for b in range(n_bins):
            a, z = lo + b * bin_m, min(hi, lo + (b + 1) * bin_m)
            sel = (centres >= a) & (centres < z) & has_ice
            if sel.any():
                out.append(round(float(edge[sel].mean()), 9))
            else:  # bins finer than the cells (or a column of water): the cell's own
                out.append(self.edge_y(0.5 * (a + z)))
        return out

    def check_room(self, where: str = "") -> None:
        """Refuse a map without room below the lowest edge for the robots and the laser."""
        need = ROBOT_ROOM_M + LASER_ROOM_M
        have = -self._y0
        if have + 1e-9 < need:
            cols = np.flatnonzero(self._edge_row == self._edge_row[self._edge_row >= 0].min())
            col = int(cols[0])
            raise MapError(
                f"not enough water below the lowest edge{where}: the edge in column {col}"
                f" (x = {col * self.cell_m:.2f} m) has only {have:.2f} m of water below it;"
                f" need {need:.1f} m ({ROBOT_ROOM_M:.0f} m to the robots' start line and"
                f" {LASER_ROOM_M:.0f} m more to the laser)"
            )


# built-in scenarios ----------------------------------------------------------
def _builtin_grids(cell_m: float) -> tuple[np.ndarray, np.ndarray, int]:
    cols = round(BUILTIN_EDGE_M / cell_m)
    water_rows = round(BUILTIN_WATER_M / cell_m)
    rows = water_rows + round(BUILTIN_ICE_M / cell_m)
    ice = np.zeros((rows, cols), dtype=bool)
    ice[water_rows:, :] = True
    return ice, np.zeros_like(ice), water_rows


def _fill_algae(
    algae: np.ndarray, water_rows: int, col_lo: int, col_hi: int, depth_m: float, cell_m: float
) -> None:
    n = round(depth_m / cell_m)
    if n > 0:
        algae[water_rows : water_rows + n, col_lo:col_hi] = True


def builtin_map(name: str, seed: int = 1, cell_m: float = BUILTIN_CELL_M) -> GridMap:
    """One of the scenarios of DESIGN.md: ``no-algae``, ``half-algae``, ``random-algae``."""
    ice, algae, water_rows = _builtin_grids(cell_m)
    cols = ice.shape[1]
    if name == "no-algae":
        pass
    elif name == "half-algae":
        _fill_algae(algae, water_rows, 0, round(3.0 / cell_m), 1.5, cell_m)
    elif name == "random-algae":
        per_bin = round(0.1 / cell_m)
        n_bins = math.ceil(cols / per_bin)
        depths = np.random.default_rng(seed).uniform(0.0, 1.5, n_bins)
        for b, depth in enumerate(depths):
            _fill_algae(
                algae, water_rows, b * per_bin, min(cols, (b + 1) * per_bin), float(depth), cell_m
            )
    else:
        raise MapError(
            f"unknown map {name!r}: use one of {', '.join(BUILTIN_NAMES)} or a .png file"
        )
    return GridMap(ice=ice, algae=algae, cell_m=cell_m, name=name)


# PNG maps ----------------------------------------------------------------------
MAX_MAP_PIXELS = 25_000_000  # 5000 x 5000 px: 250 m square at 5 cm a pixel
_ROWS_AT_ONCE = 256  # image rows classified together: bounded memory for any width


def _nearest_colour(rgb: np.ndarray) -> np.ndarray:
    """Per pixel, 0 (water), 1 (ice) or 2 (algae): the palette colour nearest to it,
    a band of rows at a time."""
    palette = np.array([WATER_RGB, ICE_RGB, ALGAE_RGB], dtype=np.int32)
    kind = np.empty(rgb.shape[:2], dtype=np.uint8)
    for r in range(0, rgb.shape[0], _ROWS_AT_ONCE):
        band = rgb[r:r + _ROWS_AT_ONCE].astype(np.int32)
        dist = ((band[:, :, None, :] - palette[None, None, :, :]) ** 2).sum(axis=-1)
        kind[r:r + _ROWS_AT_ONCE] = dist.argmin(axis=-1)
    return kind


def load_png(path: str | Path, scale_m_per_px: float = 0.05, closed: bool | None = None
             ) -> GridMap:
    """A map drawn in the thesis's colours: each pixel is water (blue), ice (white) or
    algae under ice (green), whichever its colour is nearest. Image row 0 is the top.
    ``closed``: the ice is an island whose contour the robots patrol as a ring (refused,
    with the pixel at fault, if it is not one island off the border without holes);
    None: closed if no ice touches the image's border, else open."""
    if not scale_m_per_px > 0:
        raise MapError(f"scale must be positive, got {scale_m_per_px}")
    try:
        from PIL import Image

        with warnings.catch_warnings():  # we refuse too large an image ourselves, below
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            img = Image.open(path)
        with img:
            width, height = img.size  # from the header: nothing decoded yet
            if width * height > MAX_MAP_PIXELS:
                raise MapError(
                    f"map image {path} is {width} x {height} px ({width * height / 1e6:.0f} M"
                    f" pixels); at most {MAX_MAP_PIXELS / 1e6:.0f} M are read (draw it at a"
                    " coarser scale and pass --scale)")
            rgb = np.asarray(img.convert("RGB"), dtype=np.uint8)
    except MapError:
        raise
    except Exception as exc:  # Pillow raises several types for missing or bad files
        raise MapError(f"cannot read map image {path}: {exc}") from None
    kind = _nearest_colour(rgb)[::-1]  # flip: grid row 0 is the image's bottom row
    ice = kind != 0
    if not ice.any():
        raise MapError(f"map image {path} has no ice pixel (white or green)")
    if closed is None:
        closed = not (ice[0].any() or ice[-1].any() or ice[:, 0].any() or ice[:, -1].any())
    if closed:
        gmap = GridMap(ice=ice, algae=kind == 2, cell_m=scale_m_per_px, name=str(path),
                       closed=True)
        gmap.check_ring_room(f" of map image {path}")
        return gmap
    gmap = GridMap(ice=ice, algae=kind == 2, cell_m=scale_m_per_px, name=str(path))
    height = rgb.shape[0]
    lowest = int(gmap._edge_row[gmap._edge_row >= 0].min())
    col = int(np.flatnonzero(gmap._edge_row == lowest)[0])
    try:
        gmap.check_room()
    except MapError:
        need = ROBOT_ROOM_M + LASER_ROOM_M
        raise MapError(
            f"map image {path}: not enough water below the lowest edge, at pixel"
            f" (column {col}, row {height - 1 - lowest} from the top): only"
            f" {lowest * scale_m_per_px:.2f} m ({lowest} px at {scale_m_per_px} m/px) of"
            f" water below it; need {need:.1f} m ({ROBOT_ROOM_M:.0f} m to the robots' start"
            f" line and {LASER_ROOM_M:.0f} m more to the laser)"
        ) from None
    return gmap


def write_png(gmap: GridMap, path: str | Path) -> None:
    """The map as ``load_png`` reads it: one pixel per cell in the thesis's colours,
    image row 0 the top, so ``load_png(path, gmap.cell_m)`` gives back the same grids."""
    from PIL import Image

    palette = np.array([WATER_RGB, ICE_RGB, ALGAE_RGB], dtype=np.uint8)
    kind = gmap.ice.astype(np.uint8) + gmap.algae.astype(np.uint8)  # algae is under ice
    Image.fromarray(palette[kind[::-1]], mode="RGB").save(path, format="PNG")


MAP_CHOICES = (
    f"{', '.join(BUILTIN_NAMES)}, procedural:SEED[,length=..,edge=..,amplitude=..,algae=..],"
    " floe:SEED[,shape=..,size=..,algae=..], a .png file (an island of ice in it: a closed"
    " edge) or closed:FILE.png (a closed edge, refused if its ice is not one island)"
)


def load_map(name_or_path: str, scale_m_per_px: float = 0.05, seed: int = 1) -> GridMap:
    """A built-in map by name, a procedural one by its spec (simworld.procedural; its
    seed is in the name, built at the built-ins' cell), or a PNG file by path."""
    if name_or_path in BUILTIN_NAMES:
        return builtin_map(name_or_path, seed=seed)
    if name_or_path.startswith("procedural:"):
        from simworld.procedural import procedural_map  # it imports this module

        return procedural_map(name_or_path, BUILTIN_CELL_M)
    if name_or_path.startswith("floe:"):
        from simworld.floes import floe_map  # it imports this module

        return floe_map(name_or_path, BUILTIN_CELL_M)
    if name_or_path.startswith("closed:"):
        return load_png(name_or_path.removeprefix("closed:"), scale_m_per_px, closed=True)
    if name_or_path.lower().endswith(".png") or Path(name_or_path).exists():
        return load_png(name_or_path, scale_m_per_px)
    raise MapError(f"unknown map {name_or_path!r}: use one of {MAP_CHOICES}")
