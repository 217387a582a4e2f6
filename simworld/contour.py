"""The closed edge of an island map: its ice checked to be one island with water all
round (no second island, no hole, off the image's border), its contour traced through
the pixels' sides, smoothed, and resampled by arc length into an
``agent.edgeframe.ClosedEdge``; and the true patrol depth along it, measured from the
contour along its inward normal (what the report's workload integrates).

Pure numpy: grid in, geometry out. Grid row 0 is the map's lowest row (y grows with
the row), as simworld.maps keeps it; the pixels named in a refusal are the image's
(column, row from the top), as a user finds them in a paint program.
"""

from __future__ import annotations

import math

import numpy as np

from agent.edgeframe import ClosedEdge

# The contour through the pixels' sides is a staircase one cell high; it is smoothed
# over this many cells (a Gaussian's sigma), and never less than SMOOTH_MIN_M, so that
# its direction is steady to about a hundredth of a radian: a point 1 m in from the
# edge takes its s from the edge's normal, and a staircase's wobble of the normal
# would move that s by the depth times the wobble.
SMOOTH_CELLS = 3.0
SMOOTH_MIN_M = 0.1
RESAMPLE_M = 0.02  # the smoothed contour's vertices this far apart (or a cell, if larger)
# The tightest bend accepted, m of radius: the frame of (s, d) is singular at the
# centre of a bend, and the robots start ROBOT_ROOM_M out and patrol up to the algae's
# depth in, so a tighter bend (or a narrow bay) would fold their legs into each other.
MIN_BEND_RADIUS_M = 1.0
RAY_STEP_CELLS = 0.5  # the true depth is looked for along the normal in steps this fine


class ContourError(ValueError):
    """An island map that cannot be used, with the reason and the pixel in the message."""


def _pixel(row: int, col: int, rows: int) -> str:
    return f"pixel (column {col}, row {rows - 1 - row} from the top)"


def _runs(mask: np.ndarray) -> list[list[tuple[int, int]]]:
    """Per grid row, the runs of True cells as (first column, last column)."""
    out: list[list[tuple[int, int]]] = []
    for row in mask:
        padded = np.concatenate([[False], row, [False]]).astype(np.int8)
        change = np.flatnonzero(np.diff(padded))
        out.append([(int(a), int(b) - 1) for a, b in zip(change[::2], change[1::2],
                                                         strict=True)])
    return out


def components(mask: np.ndarray, diagonal: bool) -> list[tuple[int, int, int]]:
    """The connected components of ``mask`` (4-connected, or 8-connected with
    ``diagonal``), each as (cells, row, column) of its first cell in row order: runs of
    each row joined to the overlapping runs of the row below (union-find)."""
    runs = _runs(mask)
    ids: list[list[int]] = []
    parent: list[int] = []
    first: list[tuple[int, int]] = []
    size: list[int] = []

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    reach = 1 if diagonal else 0
    for r, row_runs in enumerate(runs):
        row_ids = []
        below = runs[r - 1] if r else []
        for a, b in row_runs:
            k = len(parent)
            parent.append(k)
            first.append((r, a))
            size.append(b - a + 1)
            row_ids.append(k)
            for j, (c, d) in enumerate(below):
                if c <= b + reach and d >= a - reach:
                    ra, rb = find(k), find(ids[r - 1][j])
                    if ra != rb:
                        parent[rb] = ra
        ids.append(row_ids)
    totals: dict[int, list[int]] = {}
    for k in range(len(parent)):
        root = find(k)
        entry = totals.setdefault(root, [0, *first[k]])
        entry[0] += size[k]
        if first[k] < (entry[1], entry[2]):
            entry[1], entry[2] = first[k]
    return [(c, r, col) for c, r, col in totals.values()]


def check_island(ice: np.ndarray, where: str = "the map") -> None:
    """Refuse ice that is not one island with water all round: ice on the image's
    border, a second island, or a hole (water enclosed by the ice)."""
    rows, cols = ice.shape
    if not ice.any():
        raise ContourError(f"{where} has no ice: a closed edge needs an island")
    border = np.zeros_like(ice)
    border[0, :] = border[-1, :] = border[:, 0] = border[:, -1] = True
    touching = np.argwhere(ice & border)
    if touching.size:
        r, c = (int(v) for v in touching[0])
        raise ContourError(
            f"{where}: the island touches the image's border at {_pixel(r, c, rows)}; a"
            " closed edge needs water all round it")
    islands = sorted(components(ice, diagonal=False), reverse=True)
    if len(islands) > 1:
        cells, r, c = islands[1]
        raise ContourError(
            f"{where} has {len(islands)} islands; a closed edge is one. The second largest"
            f" ({cells} pixels) has its first cell at {_pixel(r, c, rows)}")
    waters = components(~ice, diagonal=True)
    if len(waters) > 1:
        # the island is off the border, so the sea holds the grid's first cell
        hole = min((w for w in waters if (w[1], w[2]) != (0, 0)), key=lambda w: (w[1], w[2]))
        raise ContourError(
            f"{where}: the island has a hole (water enclosed by ice) at"
            f" {_pixel(hole[1], hole[2], rows)}; a closed edge is an island without holes")


def trace(ice: np.ndarray) -> np.ndarray:
    """The island's contour through the middles of its pixels' sides (marching squares
    on the cells' centres), counterclockwise, as (x, y) in cells from the grid's
    corner (cell (row, col) has its centre at (col + 0.5, row + 0.5)). Where two ice
    cells touch only at a corner, the contour keeps them apart (ice is 4-connected)."""
    grid = np.pad(ice, 1).astype(np.int8)
    bl, br = grid[:-1, :-1], grid[:-1, 1:]
    tl, tr = grid[1:, :-1], grid[1:, 1:]
    mixed = np.argwhere((bl + br + tl + tr) % 4 != 0)
    nxt: dict[tuple[int, int], tuple[int, int]] = {}
    for r, c in mixed.tolist():
        # the block's corners counterclockwise, and each side's crossing (in half cells,
        # padded grid: centre of padded cell (r, c) at 2c + 1, 2r + 1)
        corners = (grid[r, c], grid[r, c + 1], grid[r + 1, c + 1], grid[r + 1, c])
        sides = ((2 * c + 2, 2 * r + 1), (2 * c + 3, 2 * r + 2),
                 (2 * c + 2, 2 * r + 3), (2 * c + 1, 2 * r + 2))
        starts, ends = [], []
        for k in range(4):
            a, b = corners[k], corners[(k + 1) % 4]
            if a and not b:
                starts.append(k)
            elif b and not a:
                ends.append(k)
        for k in starts:  # each start joins the end just before it, going round
            e = max((j for j in ends if j < k), default=max(ends))
            nxt[sides[k]] = sides[e]
    if not nxt:
        raise ContourError("the island has no contour")
    start = min(nxt)
    loop = [start]
    p = nxt[start]
    while p != start:
        loop.append(p)
        p = nxt[p]
        if len(loop) > len(nxt):
            raise ContourError("the island's contour does not close")
    if len(loop) != len(nxt):
        raise ContourError("the island's contour is more than one loop (a hole?)")
    pts = np.array(loop, dtype=float) * 0.5 - 1.0  # half cells -> cells, unpadded
    return pts


def _resample(pts: np.ndarray, step: float) -> np.ndarray:
    """A closed polyline resampled at equal arc length, about ``step`` apart."""
    closed = np.vstack([pts, pts[:1]])
    seg = np.hypot(*np.diff(closed, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    count = max(8, int(round(s[-1] / step)))
    at = np.arange(count) * (s[-1] / count)
    return np.column_stack([np.interp(at, s, closed[:, 0]), np.interp(at, s, closed[:, 1])])


def _smooth(pts: np.ndarray, sigma: float, step: float) -> np.ndarray:
    """A closed polyline sampled every ``step`` smoothed by a Gaussian of ``sigma``
    along it (circular convolution, by FFT)."""
    n = len(pts)
    k = np.fft.fftfreq(n, d=step)
    gain = np.exp(-0.5 * (2.0 * math.pi * k * sigma) ** 2)
    return np.column_stack([np.real(np.fft.ifft(np.fft.fft(pts[:, j]) * gain))
                            for j in range(2)])


def closed_edge(ice: np.ndarray, cell_m: float, y0: float, where: str = "the map"
                ) -> ClosedEdge:
    """The island's closed edge in the map's metres (x from the grid's left side, y
    from ``y0`` at the bottom of row 0): checked (``check_island``), traced, smoothed
    and resampled; refused if it bends tighter than MIN_BEND_RADIUS_M."""
    check_island(ice, where)
    raw = trace(ice) * cell_m + np.array([0.0, y0])
    fine = _resample(raw, 0.5 * cell_m)
    sigma = max(SMOOTH_CELLS * cell_m, SMOOTH_MIN_M)
    smooth = _smooth(fine, sigma, float(np.mean(np.hypot(*np.diff(fine, axis=0).T))))
    pts = _resample(smooth, max(RESAMPLE_M, cell_m))
    edge = ClosedEdge([(float(x), float(y)) for x, y in pts])
    kappa = np.asarray(edge.curvature)
    worst = int(np.argmax(np.abs(kappa)))
    if abs(kappa[worst]) * MIN_BEND_RADIUS_M > 1.0:
        x, y = edge.points[worst]
        col, row = int(x / cell_m), int((y - y0) / cell_m)
        kind = "bend" if kappa[worst] > 0 else "bay"
        raise ContourError(
            f"{where}: the edge turns too tightly near {_pixel(row, col, ice.shape[0])}: a"
            f" {kind} of radius {1.0 / abs(kappa[worst]):.2f} m, where at least"
            f" {MIN_BEND_RADIUS_M:g} m is needed for the robots' legs along its normals")
    return edge


def along(edge: ClosedEdge, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The contour's points and tangent directions at arc lengths ``s`` (any reals:
    they wrap), as the frame interpolates them (``ClosedEdge.point``,
    ``tangent_angle``), over arrays."""
    pts = np.asarray(edge.points)
    vs = np.append(np.asarray(edge.s), edge.length)
    w = np.mod(np.asarray(s, dtype=float), edge.length)
    x = np.interp(w, vs, np.append(pts[:, 0], pts[0, 0]))
    y = np.interp(w, vs, np.append(pts[:, 1], pts[0, 1]))
    ang = np.unwrap(np.append(edge.vertex_angle, edge.vertex_angle[0]))
    return x, y, np.interp(w, vs, ang)


def normal_depths(edge: ClosedEdge, ice: np.ndarray, algae: np.ndarray, cell_m: float,
                  y0: float, bins: int, max_depth_m: float) -> np.ndarray:
    """The algae's depth along the inward normal per bin of ``bins`` equal bins of the
    contour: the mean over points about a cell apart in the bin of how far in along
    the normal the algae runs from the edge without a gap (0 where the edge has none),
    looking no further in than ``max_depth_m``."""
    step = RAY_STEP_CELLS * cell_m
    per_bin = max(1, int(round(edge.length / bins / cell_m)))
    s = (np.arange(bins * per_bin) + 0.5) * (edge.length / (bins * per_bin))
    x, y, ang = along(edge, s)
    d = (np.arange(int(max_depth_m / step)) + 0.5) * step
    px = x[:, None] - d[None, :] * np.sin(ang)[:, None]
    py = y[:, None] + d[None, :] * np.cos(ang)[:, None]
    col = np.floor(px / cell_m).astype(int)
    row = np.floor((py - y0) / cell_m).astype(int)
    inside = (row >= 0) & (row < ice.shape[0]) & (col >= 0) & (col < ice.shape[1])
    row, col = np.where(inside, row, 0), np.where(inside, col, 0)
    is_ice = inside & ice[row, col]
    # the algae under the edge: its run from the edge in, to its first gap (further in
    # along a normal lies the floe's far side, or algae that is not this edge's)
    # (the smoothed contour may lie a cell off the pixels: water there does not end it)
    under = is_ice & algae[row, col]
    run = np.cumprod(under | (~is_ice & (d < 2.0 * cell_m)[None, :]), axis=1).astype(bool)
    depth = np.where((run & under).any(axis=1), run.sum(axis=1) * step, 0.0)
    return depth.reshape(bins, per_bin).mean(axis=1)
