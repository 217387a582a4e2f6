"""A seeded family of maps: an edge of any length (straight, sloped or curved) with
algae in steps, ramps, blooms or at random, all drawn from one seed.

``MapSpec`` names a map; its canonical string ``procedural:SEED,length=..,edge=..,
amplitude=..,algae=..`` is what ``--map`` takes and what a recording keeps, so the
name alone rebuilds the same grid. ``procedural_map`` builds that grid (pure numpy).

Three independent random streams come from the seed: the spec's fields
(``default_rng(seed)``), the edge's shape (``default_rng([seed, 1])``) and the
algae (``default_rng([seed, 2])``). Overriding a field therefore changes neither the
other fields nor, for the edge, the algae drawn (and the other way round).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from simworld.maps import (
    BUILTIN_CELL_M,
    LASER_ROOM_M,
    ROBOT_ROOM_M,
    GridMap,
    MapError,
    write_png,
)

PREFIX = "procedural:"
LENGTH_RANGE_M = (3.0, 30.0)  # what from_seed draws and the general suite deals
# what a map may be given: long enough for a hundred robots at 0.6 m each
LENGTH_LIMITS_M = (3.0, 60.0)
AMPLITUDE_RANGE_M = (0.0, 0.6)
DRAWN_AMPLITUDE_M = (0.1, 0.6)  # from_seed's range for a sloped or curved edge
EDGES = ("straight", "sloped", "curved")
ALGAE = ("none", "steps", "ramps", "blooms", "random")
MAX_ALGAE_M = 1.5  # the thesis's deepest algae
ICE_ABOVE_M = 3.0  # ice above the highest edge point: the deepest algae and as much again
CELL_RANGE_M = (0.002, 0.1)  # finer makes a 30 m map's grids hundreds of MB
DRAW_DIGITS = 2  # drawn lengths and amplitudes are whole centimetres, for readable names

CURVE_WAVELENGTH_MIN_M = 1.5
CURVE_TERMS = (1, 3)
STEP_STRETCHES = (2, 6)
BLOOM_COUNT = (1, 4)
BLOOM_WIDTH_MIN_M = 0.5
BLOOM_PEAK_M = (0.4, 1.5)
RANDOM_BIN_M = 0.1  # as the built-in random-algae: one depth per 0.1 m

# the spec string's keys and the fields they set
KEYS = {"length": "length_m", "edge": "edge", "amplitude": "amplitude_m", "algae": "algae"}
GRAMMAR = "procedural:SEED[,length=..,edge=..,amplitude=..,algae=..]"
_EDGE_STREAM, _ALGAE_STREAM = 1, 2


def _fmt(x: float) -> str:
    """The shortest text that reads back as the same float, without a trailing .0."""
    text = repr(float(x))
    return text[:-2] if text.endswith(".0") else text


@dataclass(frozen=True)
class MapSpec:
    """One map of the family; refused with the field and its allowed range if out of it."""

    seed: int
    length_m: float  # the edge's length along x, 3 to 60 m (drawn: 3 to 30)
    edge: str  # straight | sloped | curved
    amplitude_m: float  # sloped: total rise end to end; curved: max |deviation|; 0 to 0.6 m
    algae: str  # none | steps | ramps | blooms | random

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise MapError(f"seed must be an integer >= 0, got {self.seed!r}")
        for key, value in (("length", self.length_m), ("amplitude", self.amplitude_m)):
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise MapError(f"{key} must be a number of metres, got {value!r}")
        lo, hi = LENGTH_LIMITS_M
        if not lo <= self.length_m <= hi:
            raise MapError(f"length must be in [{lo:g}, {hi:g}] m, got {self.length_m!r}")
        if self.edge not in EDGES:
            raise MapError(f"edge must be one of {', '.join(EDGES)}, got {self.edge!r}")
        lo, hi = AMPLITUDE_RANGE_M
        if not lo <= self.amplitude_m <= hi:
            raise MapError(f"amplitude must be in [{lo:g}, {hi:g}] m, got {self.amplitude_m!r}")
        if self.edge == "straight" and self.amplitude_m != 0:
            raise MapError(f"amplitude must be 0 for a straight edge, got {self.amplitude_m!r}")
        if self.algae not in ALGAE:
            raise MapError(f"algae must be one of {', '.join(ALGAE)}, got {self.algae!r}")
        object.__setattr__(self, "length_m", float(self.length_m))
        object.__setattr__(self, "amplitude_m", float(self.amplitude_m))

    @classmethod
    def from_seed(cls, seed: int, **overrides: Any) -> MapSpec:
        """Every field drawn from ``default_rng(seed)``, then ``overrides`` (field names:
        length_m, edge, amplitude_m, algae) put in their place. All fields are drawn
        whatever is overridden, so an override never changes another field."""
        known = {f.name for f in fields(cls)} - {"seed"}
        unknown = set(overrides) - known
        if unknown:
            raise MapError(
                f"unknown field(s) {', '.join(sorted(unknown))}: use {', '.join(sorted(known))}"
            )
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise MapError(f"seed must be an integer >= 0, got {seed!r}")
        rng = np.random.default_rng(seed)
        length = round(float(rng.uniform(*LENGTH_RANGE_M)), DRAW_DIGITS)
        edge = EDGES[int(rng.integers(len(EDGES)))]
        amplitude = round(float(rng.uniform(*DRAWN_AMPLITUDE_M)), DRAW_DIGITS)
        algae = ALGAE[int(rng.integers(len(ALGAE)))]
        edge = overrides.get("edge", edge)
        if "amplitude_m" not in overrides and edge == "straight":
            amplitude = 0.0
        drawn = {"length_m": length, "edge": edge, "amplitude_m": amplitude, "algae": algae}
        drawn.update(overrides)
        return cls(seed=seed, **drawn)

    @classmethod
    def parse(cls, text: str) -> MapSpec:
        """``procedural:SEED`` with optional ``,key=value`` overrides (length, edge,
        amplitude, algae), each key at most once."""
        if not text.startswith(PREFIX):
            raise MapError(f"bad procedural map {text!r}: must start with {PREFIX!r} ({GRAMMAR})")
        seed_text, *parts = [p.strip() for p in text.removeprefix(PREFIX).split(",")]
        try:
            seed = int(seed_text)
        except ValueError:
            raise MapError(
                f"bad procedural map {text!r}: the seed {seed_text!r} is not an integer ({GRAMMAR})"
            ) from None
        overrides: dict[str, Any] = {}
        for part in parts:
            key, eq, value = (s.strip() for s in part.partition("="))
            if not eq or not value:
                raise MapError(f"bad procedural map {text!r}: {part!r} is not key=value")
            if key not in KEYS:
                raise MapError(
                    f"bad procedural map {text!r}: unknown key {key!r}, use {', '.join(KEYS)}"
                )
            name = KEYS[key]
            if name in overrides:
                raise MapError(f"bad procedural map {text!r}: {key} given twice")
            if name in ("length_m", "amplitude_m"):
                try:
                    overrides[name] = float(value)
                except ValueError:
                    raise MapError(
                        f"bad procedural map {text!r}: {key}={value!r} is not a number"
                    ) from None
            else:
                overrides[name] = value
        try:
            return cls.from_seed(seed, **overrides)
        except MapError as exc:
            raise MapError(f"bad procedural map {text!r}: {exc}") from None

    @property
    def name(self) -> str:
        """The canonical string: every field, so it rebuilds this map on its own."""
        return (
            f"{PREFIX}{self.seed},length={_fmt(self.length_m)},edge={self.edge},"
            f"amplitude={_fmt(self.amplitude_m)},algae={self.algae}"
        )

    def __str__(self) -> str:
        return self.name


# the edge ----------------------------------------------------------------------
def edge_curve(spec: MapSpec, x: np.ndarray) -> np.ndarray:
    """The edge's height (m) at each x, lowest point 0."""
    rng = np.random.default_rng([spec.seed, _EDGE_STREAM])
    amp, length = spec.amplitude_m, spec.length_m
    if spec.edge == "sloped":
        rising = bool(rng.integers(2))
        t = x / length
        y = amp * (t if rising else 1.0 - t)
    elif spec.edge == "curved":
        terms = int(rng.integers(CURVE_TERMS[0], CURVE_TERMS[1] + 1))
        wavelengths = rng.uniform(CURVE_WAVELENGTH_MIN_M, length, terms)
        weights = rng.uniform(0.3, 1.0, terms)
        phases = rng.uniform(0.0, 2.0 * math.pi, terms)
        y = (weights * np.sin(2.0 * math.pi * x[:, None] / wavelengths + phases)).sum(axis=1)
        peak = float(np.abs(y).max())
        y = y * (amp / peak) if peak > 0 else np.zeros_like(x)
    else:
        y = np.zeros_like(x)
    return np.asarray(y - y.min(), dtype=float)


# the algae ---------------------------------------------------------------------
def _stretch_ends(rng: np.random.Generator, length: float, lo: int, hi: int) -> np.ndarray:
    """0, the inner ends, length: lo to hi stretches of random, rarely tiny, lengths."""
    count = int(rng.integers(lo, hi + 1))
    shares = rng.dirichlet(np.full(count, 2.0))
    return np.concatenate([[0.0], np.cumsum(shares)]) * length


def algae_depths(spec: MapSpec, x: np.ndarray, cell_m: float) -> np.ndarray:
    """The algae's depth (m) above the local edge at each x, in [0, 1.5]."""
    rng = np.random.default_rng([spec.seed, _ALGAE_STREAM])
    length = spec.length_m
    if spec.algae == "steps":
        ends = _stretch_ends(rng, length, *STEP_STRETCHES)
        levels = rng.uniform(0.0, MAX_ALGAE_M, len(ends) - 1)
        index = np.clip(np.searchsorted(ends, x, side="right") - 1, 0, len(levels) - 1)
        depth = levels[index]
    elif spec.algae == "ramps":
        knots = _stretch_ends(rng, length, *STEP_STRETCHES)
        depth = np.interp(x, knots, rng.uniform(0.0, MAX_ALGAE_M, len(knots)))
    elif spec.algae == "blooms":
        count = int(rng.integers(BLOOM_COUNT[0], BLOOM_COUNT[1] + 1))
        centres = rng.uniform(0.0, length, count)
        widths = rng.uniform(BLOOM_WIDTH_MIN_M, length / 3.0, count)
        peaks = rng.uniform(*BLOOM_PEAK_M, count)
        offset = (x[:, None] - centres) / widths  # in widths: the bump spans [-0.5, 0.5]
        bumps = np.where(np.abs(offset) < 0.5, 0.5 * (1.0 + np.cos(2.0 * math.pi * offset)), 0.0)
        depth = (bumps * peaks).max(axis=1)  # overlapping blooms: the deeper one
    elif spec.algae == "random":
        per_bin = max(1, round(RANDOM_BIN_M / cell_m))
        bins = np.arange(len(x)) // per_bin
        levels = rng.uniform(0.0, MAX_ALGAE_M, int(bins[-1]) + 1)
        if bins[-1] > 0 and 2 * (len(x) - bins[-1] * per_bin) < per_bin:
            # an edge that ends less than half a column into the last one: that sliver
            # (a centimetre of 1 m deep algae on an 11.51 m edge) is the column before's,
            # not a column of its own no pass line lands in
            levels[-1] = levels[-2]
        depth = levels[bins]
    else:
        depth = np.zeros_like(x)
    return np.clip(depth, 0.0, MAX_ALGAE_M)


# the grid ----------------------------------------------------------------------
def procedural_map(spec: MapSpec | str, cell_m: float = BUILTIN_CELL_M) -> GridMap:
    """The grid of ``spec``: 2 m of water below the lowest edge point (the robots' and
    the laser's room), ice from the edge up to 3 m above its highest point, algae from
    the local edge up by its depth. Columns span exactly the edge's length from x = 0."""
    if isinstance(spec, str):
        spec = MapSpec.parse(spec)
    lo, hi = CELL_RANGE_M
    if not lo <= cell_m <= hi:
        raise MapError(f"cell must be in [{lo:g}, {hi:g}] m, got {cell_m!r}")
    cols = round(spec.length_m / cell_m)
    x = (np.arange(cols) + 0.5) * cell_m  # the columns' centres
    # a slope rises by its full amplitude between the first and the last column
    edge_x = np.linspace(0.0, spec.length_m, cols) if spec.edge == "sloped" else x
    water_rows = math.ceil((ROBOT_ROOM_M + LASER_ROOM_M) / cell_m - 1e-9)
    edge_row = water_rows + np.rint(edge_curve(spec, edge_x) / cell_m).astype(np.int64)
    algae_rows = np.rint(algae_depths(spec, x, cell_m) / cell_m).astype(np.int64)
    rows = int(edge_row.max()) + math.ceil(ICE_ABOVE_M / cell_m - 1e-9)
    row = np.arange(rows)[:, None]
    ice = row >= edge_row
    algae = ice & (row < edge_row + algae_rows)
    return GridMap(ice=ice, algae=algae, cell_m=cell_m, name=spec.name)


__all__ = [
    "ALGAE",
    "EDGES",
    "GRAMMAR",
    "MapSpec",
    "algae_depths",
    "edge_curve",
    "procedural_map",
    "write_png",
]
