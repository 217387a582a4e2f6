"""A map that changes during the run (issue 18): algae that grows or recedes, or a
second map's algae blended in, each over a window of simulated time.

Pure: the map at time t is a function of t alone (no clock, no I/O, no random draw),
so the world process and the in-process engine sense the same map at every tick. A
change moves only the algae, never the ice: the edge, its ends and its shape stay
those of the run's map (the recorder refuses a second world with another edge).

In each column the algae reaches ``n`` cells above the local edge. A change scales or
blends that extent (``Change``); the map at time t has, in a column whose extent is
``n_t`` cells against the map's own ``n_0``:

- below ``min(n_0, n_t)``: the map's own algae cells (a patch stays a patch);
- from ``n_0`` up to ``n_t`` (growth): every ice cell of the ice above the edge;
- from ``n_t`` up to ``n_0`` (recession): no algae.

So at ``n_t = n_0`` the map is exactly the run's map, before a change begins and for
every static run. ``n_t`` is rounded to whole cells; the true patrol depth the world
tells the recorder is measured from the same cells the sensors read.

``--change`` specs (``parse_changes``), repeatable, windows in seconds that must not
overlap:

- ``grow:F@T0-T1``: the algae's depth grows by the fraction F of it (0.5: by half)
  from T0 to T1, linearly; a negative F recedes;
- ``recede:F@T0-T1``: ``grow:-F``, F in [0, 1];
- ``blend:MAP@T0-T1``: the algae's depth goes linearly from the run's map's to MAP's
  (any ``--map`` name with the same ice, such as ``procedural:SEED,algae=..`` of the
  same seed).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from simworld.maps import GridMap, MapError

KINDS = ("grow", "recede", "blend")
GRAMMAR = "grow:F@T0-T1 | recede:F@T0-T1 | blend:MAP@T0-T1"
MAX_GROWTH = 10.0  # grow:F at most ten-fold more (the ice above the edge bounds it anyway)
# While a change goes on, the world tells the recorder the true patrol depth this often
# (and at each window's two ends); the report interpolates between these frames.
FRAME_EVERY_S = 1.0


class ChangeError(ValueError):
    """A ``--change`` spec that cannot be used, with what is wrong in the message."""


@dataclass(frozen=True)
class Change:
    """One change of the map over [t0, t1] s: ``grow`` by ``fraction`` of the depth
    (negative: recede), or ``blend`` to the algae of the map named ``other``."""

    kind: str
    t0: float
    t1: float
    fraction: float = 0.0
    other: str = ""

    def progress(self, t: float) -> float:
        """How far the change has gone at time ``t``: 0 before t0, 1 from t1."""
        if t <= self.t0:
            return 0.0
        if t >= self.t1:
            return 1.0
        return (t - self.t0) / (self.t1 - self.t0)

    def __str__(self) -> str:
        what = _fmt(self.fraction) if self.kind == "grow" else self.other
        return f"{self.kind}:{what}@{_fmt(self.t0)}-{_fmt(self.t1)}"


def _fmt(x: float) -> str:
    text = repr(float(x))
    return text[:-2] if text.endswith(".0") else text


def parse_change(text: str) -> Change:
    """One ``--change`` spec (``GRAMMAR``); ChangeError naming what is wrong."""
    def bad(why: str) -> ChangeError:
        return ChangeError(f"bad --change {text!r}: {why} (use {GRAMMAR})")

    kind, sep, rest = text.partition(":")
    if not sep:
        raise bad("no kind: it starts with grow:, recede: or blend:")
    if kind not in KINDS:
        raise bad(f"unknown kind {kind!r}")
    what, at, window = rest.rpartition("@")
    if not at:
        raise bad("no window: end it with @T0-T1, the seconds it starts and ends")
    start, dash, end = window.partition("-")
    try:
        t0, t1 = float(start), float(end)
    except ValueError:
        t0 = t1 = math.nan
    if not dash or not (math.isfinite(t0) and math.isfinite(t1)):
        raise bad(f"window {window!r} is not T0-T1 in seconds")
    if t0 < 0 or t1 <= t0:
        raise bad(f"window {window!r}: need 0 <= T0 < T1")
    if kind == "blend":
        if not what:
            raise bad("blend: names no map")
        return Change("blend", t0, t1, other=what)
    try:
        amount = float(what)
    except ValueError:
        raise bad(f"{kind}: {what!r} is not a number (a fraction of the depth)") from None
    if not math.isfinite(amount):
        raise bad(f"{kind}: {what!r} is not a finite number")
    if kind == "recede":
        if not 0.0 <= amount <= 1.0:
            raise bad(f"recede: {what} is not a fraction in [0, 1] of the depth")
        amount = -amount
    elif not -1.0 <= amount <= MAX_GROWTH:
        raise bad(f"grow: {what} must be in [-1, {MAX_GROWTH:g}] (a fraction of the depth;"
                  " -1 clears the algae)")
    return Change("grow", t0, t1, fraction=amount + 0.0)


def parse_changes(texts: Sequence[str]) -> tuple[Change, ...]:
    """Every ``--change`` of a run, in time order; ChangeError if one is malformed or
    two windows overlap."""
    changes = sorted((parse_change(t) for t in texts), key=lambda c: c.t0)
    for a, b in zip(changes, changes[1:], strict=False):
        if b.t0 < a.t1:
            raise ChangeError(f"--change {b} overlaps --change {a}: one change at a time "
                              "(windows may touch, not overlap)")
    return tuple(changes)


def spec_text(changes: Sequence[Change]) -> str:
    """The run's changes as one line (WorldInfo.change): the specs joined by '; '."""
    return "; ".join(str(c) for c in changes)


def windows(changes: Sequence[Change]) -> list[float]:
    """The changes' windows flat, [t0, t1, t0, t1, ...] (WorldInfo.change_windows)."""
    return [v for c in changes for v in (c.t0, c.t1)]


class ChangingMap:
    """The run's map (``base``) as ``changes`` change it with time (module docstring).

    ``load`` builds a map blended in from its name (``simworld.maps.load_map`` with the
    run's scale and seed); it must have the same grid, cell and ice as ``base``."""

    def __init__(self, base: GridMap, changes: Sequence[Change],
                 load: Callable[[str], GridMap] | None = None) -> None:
        if not changes:
            raise ChangeError("a changing map needs at least one change")
        if base.closed:
            raise ChangeError("--change: a closed edge (a ring round a floe) does not "
                              "change yet; only an open edge's algae does")
        self.base = base
        self.changes = tuple(changes)
        cell = base.cell_m
        rows = np.arange(base.rows)[:, None]
        self._edge = base.edge_rows
        has_ice = self._edge >= 0
        self._n0 = np.where(has_ice, np.rint(base.algae_extent_m / cell), 0).astype(np.int64)
        # the ice above the local edge, in cells, up to the first water above it: how far
        # algae can grow
        above = (rows >= self._edge[None, :]) & has_ice[None, :]
        water_above = above & ~base.ice
        first_water = np.where(water_above.any(axis=0), water_above.argmax(axis=0), base.rows)
        self._run = np.where(has_ice, first_water - self._edge, 0).astype(np.int64)
        # per (row, column): the highest extent (cells above the edge) of the map's own
        # algae at or below the row; what a receding extent leaves of a patchy column
        own = np.where(base.algae, rows + 1 - self._edge[None, :], 0)
        self._top_below = np.maximum.accumulate(own, axis=0)
        self._bin_of: tuple[tuple[float, int], np.ndarray, np.ndarray, np.ndarray] | None = None
        self._others: dict[str, np.ndarray] = {}
        for c in self.changes:
            if c.kind == "blend" and c.other not in self._others:
                self._others[c.other] = self._blend_extent(c.other, load)

    def _blend_extent(self, name: str, load: Callable[[str], GridMap] | None) -> np.ndarray:
        if load is None:
            raise ChangeError(f"--change blend:{name}: no way to load the map here")
        try:
            other = load(name)
        except MapError as exc:
            raise ChangeError(f"--change blend:{name}: {exc}") from None
        base = self.base
        if (other.cell_m != base.cell_m or other.ice.shape != base.ice.shape
                or not np.array_equal(other.ice, base.ice)):
            raise ChangeError(
                f"--change blend:{name}: its ice differs from the run's map {base.name}"
                f" ({other.ice.shape[1]} x {other.ice.shape[0]} cells of {other.cell_m:g} m"
                f" against {base.cols} x {base.rows} of {base.cell_m:g} m, or another edge);"
                " a blend changes only the algae: take a map with the same ice (for a"
                " procedural map, the same seed and fields but algae=)")
        return np.rint(other.algae_extent_m / base.cell_m).astype(np.float64)

    # the map at time t -------------------------------------------------------------
    def started(self, t: float) -> bool:
        """Whether the map at ``t`` may differ from the run's map (a change began)."""
        return t > self.changes[0].t0

    def extent_cells(self, t: float) -> np.ndarray:
        """Per column, how many cells above the local edge the algae reaches at ``t``
        (before rounding: the run's map's extent, scaled and blended in turn)."""
        extent = self._n0.astype(np.float64)
        for c in self.changes:
            p = c.progress(t)
            if p == 0.0:
                break  # windows are in order and do not overlap: none later began
            if c.kind == "grow":
                extent = extent * (1.0 + c.fraction * p)
            else:
                extent = (1.0 - p) * extent + p * self._others[c.other]
        return np.maximum(np.floor(extent + 0.5), 0.0).astype(np.int64)

    def algae_at(self, x: float, y: float, extent: np.ndarray) -> bool:
        """The algae sensor at (x, y) on the map whose extents are ``extent``
        (``extent_cells``)."""
        cell = self.base.cell_of(x, y)
        if cell is None:
            return False
        row, col = cell
        if not self.base.ice[row, col]:
            return False
        h = row - int(self._edge[col])
        n_t = int(extent[col])
        if h < int(self._n0[col]):
            return h < n_t and bool(self.base.algae[row, col])
        return h < n_t and h < int(self._run[col])

    def algae_m(self, t: float) -> np.ndarray:
        """Per column, the algae's true extent above the local edge at ``t``, m (what
        ``GridMap.algae_extent_m`` is of a static map), from the cells ``algae_at``
        reads."""
        n_t = self.extent_cells(t)
        grown = np.maximum(self._n0, np.minimum(n_t, self._run))
        cols = np.arange(self.base.cols)
        row = np.clip(self._edge + n_t - 1, 0, self.base.rows - 1)
        left = np.where(n_t >= 1, self._top_below[row, cols], 0)
        cells = np.where(n_t >= self._n0, grown, left)
        return np.where(self._edge >= 0, cells, 0) * self.base.cell_m

    def patrol_depth_bins(self, t: float, bin_m: float) -> list[float]:
        """True patrol depth per bin at ``t`` (``GridMap.patrol_depth_bins``)."""
        if not self.started(t):
            return self.base.patrol_depth_bins(bin_m)
        return self._bins(self.algae_m(t), bin_m)

    def _bins(self, algae_m: np.ndarray, bin_m: float) -> list[float]:
        """``GridMap.patrol_depth_bins`` of the extents ``algae_m``, vectorised (a
        frame a second of a change must not cost the run its speed)."""
        base = self.base
        lo, hi = base.edge_lo, base.edge_hi
        n_bins = max(1, math.ceil((hi - lo) / bin_m - 1e-9))
        key = (bin_m, n_bins)
        if self._bin_of is None or self._bin_of[0] != key:
            sides = lo + bin_m * np.arange(n_bins + 1)
            sides[-1] = min(hi, sides[-1])
            centres = (np.arange(base.cols) + 0.5) * base.cell_m
            b = np.searchsorted(sides, centres, side="right") - 1
            inside = (b >= 0) & (b < n_bins) & (centres < sides[-1])
            mids = 0.5 * (sides[:-1] + sides[1:])
            under = np.clip(np.floor(mids / base.cell_m).astype(np.int64), 0, base.cols - 1)
            self._bin_of = (key, b[inside], inside, under)
        _, b, inside, under = self._bin_of
        depth = np.maximum(algae_m, base.min_depth)
        total = np.bincount(b, weights=depth[inside], minlength=n_bins)
        count = np.bincount(b, minlength=n_bins)
        out = np.where(count > 0, total / np.maximum(count, 1), depth[under])
        return [round(float(v), 9) for v in out]

    # what the world tells the recorder ---------------------------------------------
    def frame_due(self, k: int, dt: float) -> bool:
        """Whether tick ``k`` (of ``dt`` s) begins a new frame of the true depth: in a
        change's window, every FRAME_EVERY_S and at its two ends (the first tick at or
        after each)."""
        every = max(1, round(FRAME_EVERY_S / dt))
        for c in self.changes:
            k0, k1 = math.ceil(c.t0 / dt - 1e-9), math.ceil(c.t1 / dt - 1e-9)
            if k0 <= k <= k1 and (k % every == 0 or k in (k0, k1)):
                return True
        return False

    @property
    def spec(self) -> str:
        return spec_text(self.changes)

    @property
    def windows(self) -> list[float]:
        return windows(self.changes)


def frames(change: ChangingMap, ticks: int, dt: float, bin_m: float
           ) -> tuple[list[float], list[list[float]]]:
    """The frames of the true patrol depth a run of ``ticks`` tells the recorder, as
    the world sends them (at tick 0 and every ``frame_due`` tick): their times and
    depth profiles."""
    times, depths = [0.0], [change.patrol_depth_bins(0.0, bin_m)]
    for k in range(1, ticks):
        if change.frame_due(k, dt):
            times.append(k * dt)
            depths.append(change.patrol_depth_bins(k * dt, bin_m))
    return times, depths


CHANGE_HELP = (
    "the map changes during the run (repeatable; windows in simulated seconds, not "
    "overlapping): grow:F@T0-T1 (the algae's depth grows by the fraction F of it from "
    "T0 to T1, linearly; F < 0 recedes), recede:F@T0-T1 (grow:-F), blend:MAP@T0-T1 "
    "(the algae goes over to MAP's, a --map name with the same ice); e.g. "
    "grow:0.5@60-660. An open edge's algae only, with --sensors ideal")


def changing_map(gmap: GridMap, specs: Sequence[str], scale: float = 0.05, seed: int = 1
                 ) -> ChangingMap | None:
    """The run's map as ``--change`` ``specs`` change it; None without any. ChangeError
    naming what is wrong (a spec, an overlap, a map blended in that does not fit)."""
    if not specs:
        return None
    from simworld.maps import load_map  # the same loader as --map's

    return ChangingMap(gmap, parse_changes(specs), lambda name: load_map(name, scale, seed))
