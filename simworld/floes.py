"""A seeded family of closed edges: ice floes with water all round, round, elongated
or with a bay, and algae along the inside of their edge in blooms or at random.

``FloeSpec`` names a floe; its canonical string ``floe:SEED,shape=..,size=..,algae=..``
is what ``--map`` takes and what a recording keeps, so the name alone rebuilds the same
grid (as ``simworld.procedural`` does for open edges). ``floe_map`` builds the grid
(pure numpy): the floe as a signed distance (negative inside), the algae where the
distance in from the edge is under the depth profile at that bearing from the floe's
centre. The GridMap it returns has a closed edge (``GridMap.closed_edge``), traced from
the grid's pixels as a PNG's would be.

Independent random streams from the seed: the spec's fields (``default_rng(seed)``),
the shape's orientation and wobble (``default_rng([seed, 1])``), the algae
(``default_rng([seed, 2])``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from simworld.maps import BUILTIN_CELL_M, LASER_ROOM_M, ROBOT_ROOM_M, GridMap, MapError

PREFIX = "floe:"
SHAPES = ("round", "elongated", "bay")
ALGAE = ("none", "blooms", "random")
SIZE_RANGE_M = (2.5, 8.0)  # the floe's radius (round), its caps' scale (elongated)
DRAWN_SIZE_M = (2.5, 4.0)
MAX_ALGAE_M = 0.8  # under the tightest bend's radius (0.65 of the smallest size)
WATER_ROOM_M = ROBOT_ROOM_M + LASER_ROOM_M + 0.5  # water round the floe's extent
GRAMMAR = "floe:SEED[,shape=round|elongated|bay,size=..,algae=none|blooms|random]"
BAY_DEPTH, BAY_WIDTH_RAD = 0.35, 0.6
KEYS = {"shape": "shape", "size": "size_m", "algae": "algae"}
_SHAPE_STREAM, _ALGAE_STREAM = 1, 2


@dataclass(frozen=True)
class FloeSpec:
    """One floe of the family; refused with the field and its range if out of it."""

    seed: int
    shape: str  # round | elongated | bay
    size_m: float  # m: round, the radius; elongated, its width; bay, the floe's radius
    algae: str  # none | blooms | random

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise MapError(f"seed must be an integer >= 0, got {self.seed!r}")
        if self.shape not in SHAPES:
            raise MapError(f"shape must be one of {', '.join(SHAPES)}, got {self.shape!r}")
        if isinstance(self.size_m, bool) or not isinstance(self.size_m, int | float):
            raise MapError(f"size must be a number of metres, got {self.size_m!r}")
        lo, hi = SIZE_RANGE_M
        if not lo <= self.size_m <= hi:
            raise MapError(f"size must be in [{lo:g}, {hi:g}] m, got {self.size_m!r}")
        if self.algae not in ALGAE:
            raise MapError(f"algae must be one of {', '.join(ALGAE)}, got {self.algae!r}")
        object.__setattr__(self, "size_m", float(self.size_m))

    @classmethod
    def from_seed(cls, seed: int, **overrides: Any) -> FloeSpec:
        """Every field drawn from ``default_rng(seed)``, then ``overrides`` in place."""
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise MapError(f"seed must be an integer >= 0, got {seed!r}")
        rng = np.random.default_rng(seed)
        drawn: dict[str, Any] = {
            "shape": SHAPES[int(rng.integers(len(SHAPES)))],
            "size_m": round(float(rng.uniform(*DRAWN_SIZE_M)), 2),
            "algae": ALGAE[1 + int(rng.integers(len(ALGAE) - 1))],
        }
        unknown = set(overrides) - set(drawn)
        if unknown:
            raise MapError(f"unknown field(s) {', '.join(sorted(unknown))}")
        drawn.update(overrides)
        return cls(seed=seed, **drawn)

    @classmethod
    def parse(cls, text: str) -> FloeSpec:
        """``floe:SEED`` with optional ``,key=value`` overrides (shape, size, algae)."""
        if not text.startswith(PREFIX):
            raise MapError(f"a floe map is {GRAMMAR}, got {text!r}")
        head, *items = text.removeprefix(PREFIX).split(",")
        try:
            seed = int(head)
        except ValueError:
            raise MapError(f"bad seed {head!r} in {text!r}: {GRAMMAR}") from None
        overrides: dict[str, Any] = {}
        for item in items:
            key, eq, value = item.partition("=")
            if not eq or key not in KEYS:
                raise MapError(f"bad field {item!r} in {text!r}: use {', '.join(KEYS)}")
            if key == "size":
                try:
                    overrides["size_m"] = float(value)
                except ValueError:
                    raise MapError(f"size must be a number of metres, got {value!r}") from None
            else:
                overrides[KEYS[key]] = value
        return cls.from_seed(seed, **overrides)

    def name(self) -> str:
        size = repr(self.size_m).removesuffix(".0")
        return f"{PREFIX}{self.seed},shape={self.shape},size={size},algae={self.algae}"


def _shape(spec: FloeSpec, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The floe's signed distance (negative in the ice; radial for the round ones),
    about its centre at 0, 0."""
    rng = np.random.default_rng([spec.seed, _SHAPE_STREAM])
    turn = float(rng.uniform(0.0, 2.0 * math.pi))
    c, s = math.cos(turn), math.sin(turn)
    u, v = c * x + s * y, -s * x + c * y
    size = spec.size_m
    if spec.shape == "round":
        wobble = float(rng.uniform(0.02, 0.05))
        return np.hypot(u, v) - size * (1.0 + wobble * np.cos(3.0 * np.arctan2(v, u)))
    if spec.shape == "elongated":  # a capsule twice as long as it is wide
        cap = 0.65 * size
        half = 1.3 * size
        along = np.clip(u, -half, half)
        return np.hypot(u - along, v) - cap
    # a round floe with a bay: its radius dips by BAY_DEPTH of itself over about
    # BAY_WIDTH_RAD either side of the bay's bearing (the edge concave there, with a
    # radius of curvature of 1.3 of the floe's, and 0.62 of it at the bay's shoulders)
    bearing = np.arctan2(v, u)
    dip = BAY_DEPTH * np.exp((np.cos(bearing) - 1.0) / BAY_WIDTH_RAD ** 2)
    return np.hypot(u, v) - size * (1.0 - dip)


def _extent(spec: FloeSpec) -> float:
    """Half the side of a square about the centre that holds the floe."""
    return (2.0 if spec.shape == "elongated" else 1.1) * spec.size_m


def _algae_depth(spec: FloeSpec, bearing: np.ndarray) -> np.ndarray:
    """The algae's depth in from the edge at each bearing from the floe's centre."""
    rng = np.random.default_rng([spec.seed, _ALGAE_STREAM])
    if spec.algae == "none":
        return np.zeros(bearing.shape)
    if spec.algae == "blooms":
        depth = np.zeros(bearing.shape)
        for _ in range(int(rng.integers(1, 4))):
            mu = float(rng.uniform(0.0, 2.0 * math.pi))
            peak = float(rng.uniform(0.4, MAX_ALGAE_M))
            width = float(rng.uniform(0.3, 0.8))  # rad
            depth = np.maximum(depth, peak * np.exp((np.cos(bearing - mu) - 1.0) / width ** 2))
        return depth
    # random: every 0.1 m of the edge (at the floe's size) its own depth
    count = max(8, int(round(2.0 * math.pi * spec.size_m / 0.1)))
    depths = rng.uniform(0.0, MAX_ALGAE_M, count)
    index = np.floor(np.mod(bearing, 2.0 * math.pi) / (2.0 * math.pi) * count).astype(int)
    return depths[np.minimum(index, count - 1)]


def floe_map(text: str | FloeSpec, cell_m: float = BUILTIN_CELL_M) -> GridMap:
    """The grid of a floe spec (its canonical name as the map's name), with its closed
    edge traced from the pixels."""
    spec = text if isinstance(text, FloeSpec) else FloeSpec.parse(text)
    half = _extent(spec) + WATER_ROOM_M
    n = int(math.ceil(2.0 * half / cell_m))
    centres = (np.arange(n) + 0.5) * cell_m - half
    x, y = np.meshgrid(centres, centres)  # row r is y = centres[r]: row 0 the lowest
    dist = _shape(spec, x, y)
    ice = dist < 0.0
    algae = ice & (-dist < _algae_depth(spec, np.arctan2(y, x)))
    return GridMap(ice=ice, algae=algae, cell_m=cell_m, name=spec.name(), closed=True)
