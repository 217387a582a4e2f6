"""The procedural map family: specs drawn from a seed, their canonical strings, the
grids they build, the PNG round trip and the ``btrack maps`` command."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from simworld.maps import MapError, builtin_map, load_map, load_png, write_png
from simworld.procedural import (
    ALGAE,
    EDGES,
    MapSpec,
    algae_depths,
    edge_curve,
    procedural_map,
)
from simworld.world import World

REPO = Path(__file__).resolve().parents[1]
SEEDS = range(200)


def _columns(gmap) -> tuple[np.ndarray, np.ndarray]:
    """Local edge y and algae depth of every column, through GridMap's own methods."""
    x = (np.arange(gmap.cols) + 0.5) * gmap.cell_m
    return (np.array([gmap.edge_y(v) for v in x]), np.array([gmap.algae_depth(v) for v in x]))


specs = st.builds(
    lambda seed, length, edge, amplitude, algae: MapSpec(
        seed, length, edge, 0.0 if edge == "straight" else amplitude, algae
    ),
    st.integers(0, 2**40),
    st.floats(3.0, 30.0),
    st.sampled_from(EDGES),
    st.floats(0.0, 0.6),
    st.sampled_from(ALGAE),
)


# specs ------------------------------------------------------------------------
def test_drawn_fields_stay_in_range_and_cover_every_kind() -> None:
    drawn = [MapSpec.from_seed(s) for s in SEEDS]
    assert {d.edge for d in drawn} == set(EDGES)
    assert {d.algae for d in drawn} == set(ALGAE)
    for d in drawn:
        assert 3.0 <= d.length_m <= 30.0
        if d.edge == "straight":
            assert d.amplitude_m == 0.0
        else:
            assert 0.1 <= d.amplitude_m <= 0.6
    lengths = [d.length_m for d in drawn]
    assert min(lengths) < 6.0 and max(lengths) > 27.0  # the whole range, not one corner


def test_same_seed_same_spec_and_grid_other_seed_differs() -> None:
    for seed in (0, 11, 12345):
        a, b = MapSpec.from_seed(seed), MapSpec.from_seed(seed)
        assert a == b
        ma, mb = procedural_map(a), procedural_map(b)
        assert np.array_equal(ma.ice, mb.ice) and np.array_equal(ma.algae, mb.algae)
    # one shape, two seeds: the edge and the algae differ, not only the drawn fields
    fixed = {"length_m": 8.0, "edge": "curved", "amplitude_m": 0.4, "algae": "blooms"}
    one = procedural_map(MapSpec.from_seed(1, **fixed))
    two = procedural_map(MapSpec.from_seed(2, **fixed))
    assert not np.array_equal(one.ice, two.ice)
    assert not np.array_equal(one.algae, two.algae)


def test_overrides_leave_the_other_fields_as_drawn() -> None:
    for seed in range(40):
        drawn = MapSpec.from_seed(seed)
        other = MapSpec.from_seed(seed, algae="ramps", length_m=12.5)
        assert (other.edge, other.amplitude_m) == (drawn.edge, drawn.amplitude_m)
        assert (other.algae, other.length_m) == ("ramps", 12.5)
        curved = MapSpec.from_seed(seed, edge="curved")
        assert curved.length_m == drawn.length_m and curved.algae == drawn.algae
        assert 0.1 <= curved.amplitude_m <= 0.6  # drawn even when the seed's edge is straight
        assert MapSpec.from_seed(seed, edge="straight").amplitude_m == 0.0


def test_the_algae_does_not_depend_on_the_edge() -> None:
    base = {"length_m": 6.0, "amplitude_m": 0.5, "algae": "steps"}
    depths = [
        _columns(procedural_map(MapSpec.from_seed(3, edge=e, **base)))[1]
        for e in ("sloped", "curved")
    ]
    assert np.array_equal(depths[0], depths[1])


@settings(max_examples=200, deadline=None)
@given(specs)
def test_canonical_string_round_trips(spec: MapSpec) -> None:
    assert str(spec) == spec.name
    assert spec.name.startswith(f"procedural:{spec.seed},length=")
    assert MapSpec.parse(spec.name) == spec


def test_parse_short_and_partial_forms() -> None:
    assert MapSpec.parse("procedural:9") == MapSpec.from_seed(9)
    spec = MapSpec.parse("procedural:9, length=12 ,edge=curved,amplitude=0.4,algae=blooms")
    assert spec == MapSpec(9, 12.0, "curved", 0.4, "blooms")
    assert spec.name == "procedural:9,length=12,edge=curved,amplitude=0.4,algae=blooms"
    assert MapSpec.parse("procedural:9,algae=none").length_m == MapSpec.from_seed(9).length_m


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("procedural:", "seed '' is not an integer"),
        ("procedural:abc", "seed 'abc' is not an integer"),
        ("procedural:-1", "seed must be an integer >= 0"),
        ("procedural:1,length=2.9", r"length must be in \[3, 60\] m, got 2.9"),
        ("procedural:1,length=61", r"length must be in \[3, 60\] m"),
        ("procedural:1,length=nan", r"length must be in \[3, 60\] m"),
        ("procedural:1,length=long", "length='long' is not a number"),
        ("procedural:1,edge=sloped,amplitude=0.7", r"amplitude must be in \[0, 0.6\] m"),
        ("procedural:1,edge=sloped,amplitude=-0.1", r"amplitude must be in \[0, 0.6\] m"),
        ("procedural:1,edge=straight,amplitude=0.2", "amplitude must be 0 for a straight edge"),
        ("procedural:1,edge=wavy", "edge must be one of straight, sloped, curved"),
        ("procedural:1,algae=moss", "algae must be one of none, steps, ramps, blooms, random"),
        ("procedural:1,depth=1", "unknown key 'depth', use length, edge, amplitude, algae"),
        ("procedural:1,edge", "'edge' is not key=value"),
        ("procedural:1,edge=", "'edge=' is not key=value"),
        ("procedural:1,algae=none,algae=steps", "algae given twice"),
    ],
)
def test_bad_specs_are_refused_by_name(text: str, match: str) -> None:
    with pytest.raises(MapError, match=match):
        MapSpec.parse(text)
    with pytest.raises(MapError, match=match):
        load_map(text)


def test_bad_fields_and_cells_are_refused() -> None:
    with pytest.raises(MapError, match="must start with 'procedural:'"):
        MapSpec.parse("procedural")
    with pytest.raises(MapError, match="length must be in"):
        MapSpec(1, 2.0, "straight", 0.0, "none")
    with pytest.raises(MapError, match="length must be a number"):
        MapSpec(1, "12", "straight", 0.0, "none")  # type: ignore[arg-type]
    with pytest.raises(MapError, match="unknown field"):
        MapSpec.from_seed(1, depth_m=1.0)
    with pytest.raises(MapError, match=r"cell must be in \[0.002, 0.1\] m"):
        procedural_map(MapSpec.from_seed(1), cell_m=0.5)
    with pytest.raises(MapError, match=r"procedural:SEED\[,length=..,edge=.."):
        load_map("no-such-map")


# grids ------------------------------------------------------------------------
GRID_SEEDS = range(10)


@pytest.mark.parametrize("seed", GRID_SEEDS)
def test_grid_geometry_room_and_depths(seed: int) -> None:
    spec = MapSpec.from_seed(seed)
    gmap = procedural_map(spec)
    assert gmap.name == spec.name
    assert gmap.cols == round(spec.length_m / 0.01)
    assert (gmap.edge_lo, gmap.edge_hi) == (0.0, pytest.approx(spec.length_m))
    gmap.check_room()
    assert gmap.y_bottom == pytest.approx(-2.0)  # exactly the robots' and the laser's room
    edge, depth = _columns(gmap)
    assert edge.min() == 0.0
    assert gmap.y_top == pytest.approx(edge.max() + 3.0)
    assert depth.min() >= 0.0 and depth.max() <= 1.5 + 1e-9
    rise = edge.max() - edge.min()
    if spec.edge == "straight":
        assert rise == 0.0
    elif spec.edge == "sloped":
        assert rise == pytest.approx(spec.amplitude_m, abs=0.005)
        assert np.all(np.diff(edge) >= 0) or np.all(np.diff(edge) <= 0)
    else:  # max |deviation| from the centre line is the amplitude
        assert spec.amplitude_m - 0.01 <= rise <= 2 * spec.amplitude_m + 0.01
    _assert_algae_from_local_edge(gmap)


def _assert_algae_from_local_edge(gmap) -> None:
    """Each column's algae is one run of cells starting at its local edge."""
    edge_row = gmap.ice.argmax(axis=0)
    count = gmap.algae.sum(axis=0)
    rows = np.arange(gmap.rows)[:, None]
    assert np.array_equal(gmap.algae, (rows >= edge_row) & (rows < edge_row + count))
    _, depth = _columns(gmap)
    assert depth == pytest.approx(count * gmap.cell_m)


@settings(max_examples=25, deadline=None)
@given(specs, st.sampled_from([0.02, 0.03, 0.05]))
def test_any_spec_builds_a_usable_grid(spec: MapSpec, cell_m: float) -> None:
    gmap = procedural_map(spec, cell_m)
    gmap.check_room()
    assert gmap.cols == round(spec.length_m / cell_m)
    assert 0.0 <= gmap.algae.sum(axis=0).max() * cell_m <= 1.5 + 1e-9
    _assert_algae_from_local_edge(gmap)
    bins = gmap.patrol_depth_bins(0.1)
    assert min(bins) >= 0.3 - 1e-9 and max(bins) <= 1.5 + 1e-9


def test_each_algae_kind_has_its_shape() -> None:
    x = (np.arange(2000) + 0.5) * 0.01
    depth = {kind: algae_depths(MapSpec(4, 20.0, "straight", 0.0, kind), x, 0.01) for kind in ALGAE}
    assert not depth["none"].any()
    assert 2 <= len(np.unique(depth["steps"])) <= 6
    jumps = np.abs(np.diff(depth["ramps"]))
    assert jumps.max() < 0.1 and len(np.unique(depth["ramps"])) > 100  # continuous, sloping
    assert 0.39 <= depth["blooms"].max() <= 1.5 and (depth["blooms"] == 0).any()
    per_bin = depth["random"].reshape(-1, 10)  # 0.1 m bins of ten 1 cm columns
    assert (per_bin == per_bin[:, :1]).all() and len(np.unique(per_bin[:, 0])) == 200


def test_random_algae_leaves_no_sliver_of_a_column_at_the_edges_end() -> None:
    """An edge that ends a centimetre into a 0.1 m column: that centimetre is the
    column before's (no pass line lands in it, and 1 m of algae there was 7 mm^2 of
    workload no robot could see); one that ends past a column's middle keeps it."""
    for length, own in ((11.51, False), (11.57, True)):
        spec = MapSpec(740243, length, "straight", 0.0, "random")
        x = (np.arange(round(length / 0.01)) + 0.5) * 0.01
        depth = algae_depths(spec, x, 0.01)
        last = depth[x > 11.5]
        assert (last == last[0]).all()
        assert bool(last[0] != depth[x < 11.5][-1]) is own
        assert len(np.unique(depth[(x > 11.4) & (x < 11.5)])) == 1


def test_curved_edge_peak_is_the_amplitude() -> None:
    x = (np.arange(1500) + 0.5) * 0.01
    for seed in range(10):
        y = edge_curve(MapSpec(seed, 15.0, "curved", 0.3, "none"), x)
        assert y.min() == 0.0 and 0.3 - 1e-9 <= y.max() <= 0.6 + 1e-9


def test_load_map_and_world_take_a_procedural_name() -> None:
    gmap = load_map("procedural:21,length=5,edge=sloped,amplitude=0.3")
    spec = MapSpec.parse(gmap.name)
    assert (spec.seed, spec.length_m, spec.edge, spec.amplitude_m) == (21, 5.0, "sloped", 0.3)
    assert gmap.cell_m == 0.01
    world = World(gmap, 3, seed=1)
    for x, y, _ in (world.truth(i) for i in range(3)):
        assert y == pytest.approx(-1.0) and not gmap.ice_at(x, y)


# PNG ----------------------------------------------------------------------------
@pytest.mark.parametrize("cell_m", [0.01, 0.04])
def test_png_round_trip(tmp_path: Path, cell_m: float) -> None:
    gmap = procedural_map(MapSpec(8, 7.5, "curved", 0.45, "blooms"), cell_m)
    path = tmp_path / "map.png"
    write_png(gmap, path)
    back = load_png(path, scale_m_per_px=gmap.cell_m)
    assert np.array_equal(back.ice, gmap.ice) and np.array_equal(back.algae, gmap.algae)
    assert back.patrol_depth_bins() == gmap.patrol_depth_bins()
    half = builtin_map("half-algae")
    write_png(half, tmp_path / "half.png")
    again = load_png(tmp_path / "half.png", half.cell_m)
    assert np.array_equal(again.algae, half.algae)


# btrack maps --------------------------------------------------------------------
def _maps(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "btrack", "maps", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_maps_command_writes_pngs_and_an_index(tmp_path: Path) -> None:
    out = tmp_path / "family"
    result = _maps(
        "--seed",
        "5",
        "--count",
        "3",
        "--out",
        str(out),
        "--length",
        "4",
        "--algae",
        "steps",
        "--cell",
        "0.02",
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert len(lines) == 3
    index = json.loads((out / "maps.json").read_text())["maps"]
    assert [e["file"] for e in index] == [f"procedural-{s}.png" for s in (5, 6, 7)]
    for line, entry in zip(lines, index, strict=True):
        spec = MapSpec.parse(entry["spec"])
        assert spec == MapSpec.from_seed(entry["seed"], length_m=4.0, algae="steps")
        assert entry["spec"] in line and entry["file"] in line
        assert (entry["scale"], entry["length_m"], entry["algae"]) == (0.02, 4.0, "steps")
        assert entry["edge"] == spec.edge and entry["amplitude_m"] == spec.amplitude_m
        assert entry["sim"] == f"btrack sim --map {out / entry['file']} --scale 0.02"
        back = load_png(out / entry["file"], entry["scale"])
        built = procedural_map(spec, 0.02)
        assert np.array_equal(back.ice, built.ice) and np.array_equal(back.algae, built.algae)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--count", "2"], "the following arguments are required: --seed"),
        (["--seed", "-1"], "--seed: must be >= 0"),
        (["--seed", "1", "--count", "0"], "--count: must be >= 1"),
        (["--seed", "1", "--length", "70"], r"--length: must be in \[3, 60\] m, got 70"),
        (["--seed", "1", "--amplitude", "x"], "--amplitude: not a number: 'x'"),
        (["--seed", "1", "--edge", "wavy"], "--edge: invalid choice: 'wavy'"),
        (["--seed", "1", "--cell", "0"], r"--cell: must be in \[0.002, 0.1\] m"),
        (
            ["--seed", "1", "--edge", "straight", "--amplitude", "0.2"],
            "amplitude must be 0 for a straight edge",
        ),
    ],
)
def test_maps_command_refuses_bad_values(tmp_path: Path, args: list[str], match: str) -> None:
    result = _maps(*args, "--out", str(tmp_path / "x"))
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert re.search(match, result.stderr), result.stderr
    assert not (tmp_path / "x").exists()
