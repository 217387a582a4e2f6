"""The simulated LMS 2xx and the Scan message: geometry, occlusion, misses, noise,
round trip on the wire and malformed scans refused."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest

from simworld.laser import LMS_BEAMS, Laser, Scanner, box_walls, scanner_count, scanner_row
from wire import DecodeError, Scan, decode, encode

SCANNER = Scanner(3.0, -2.0)


def test_lms_geometry_and_misses_at_max_range() -> None:
    laser = Laser(SCANNER)
    ranges = laser.scan(np.empty((0, 2)))
    assert len(ranges) == LMS_BEAMS == 361
    assert all(r == 8.0 for r in ranges)
    angles = SCANNER.theta + SCANNER.angles()
    assert math.isclose(angles[0], 0.0, abs_tol=1e-12)
    assert math.isclose(angles[-1], math.pi) and math.isclose(angles[1], math.radians(0.5))


def test_robot_straight_ahead_and_hiding_another() -> None:
    laser = Laser(SCANNER, noise_m=0.0)
    exact = laser.exact(np.array([[3.0, 0.0], [3.0, 1.0]]))
    assert math.isclose(exact[180], 2.0 - 0.17)  # the middle beam hits the front robot
    assert exact.max() == 8.0 and (exact < 3.0).sum() == (exact < 8.0).sum()  # 2nd hidden


def test_noise_is_about_the_configured_std_and_seeded() -> None:
    centres = np.array([[3.0, 0.0]])
    exact = Laser(SCANNER, noise_m=0.0).exact(centres)
    hit = exact < 8.0
    errors = np.concatenate([
        np.asarray(Laser(SCANNER, noise_m=0.01, seed=s).scan(centres))[hit] - exact[hit]
        for s in range(50)
    ])
    assert 0.008 < errors.std() < 0.012
    assert Laser(SCANNER, seed=3).scan(centres) == Laser(SCANNER, seed=3).scan(centres)


def test_walls_close_the_view() -> None:
    laser = Laser(SCANNER, noise_m=0.0, walls=box_walls(-1.0, -2.5, 7.0, 4.0))
    exact = laser.exact(np.empty((0, 2)))
    assert exact.max() < 8.0 and math.isclose(exact[180], 6.0)


def scan(**kw: object) -> Scan:
    base: dict[str, object] = dict(t=1.0, k=10, ranges=[8.0] * 361, scanner_x=3.0,
                                   scanner_y=-2.0, scanner_theta=math.pi / 2)
    base.update(kw)
    return Scan(**base)  # type: ignore[arg-type]


def test_scan_round_trip() -> None:
    msg = scan(ranges=Laser(SCANNER).scan(np.array([[2.0, 0.5]])))
    assert decode(Scan, encode(msg)) == msg


@pytest.mark.parametrize("bad", [
    {"ranges": [1.0, float("nan")]},
    {"ranges": [1.0, 9.0]},
    {"ranges": [-0.1]},
    {"ranges": []},
    {"ranges": ["1.0"]},
    {"angle_step": 0.0},
    {"k": -1},
    {"scanner": 1},  # of a row of one
    {"scanner": -1, "scanners": 2},
    {"scanner": 0, "scanners": 17},
])
def test_malformed_scans_are_refused(bad: dict[str, object]) -> None:
    raw = msgpack.packb({**scan().__dict__, **bad})
    with pytest.raises(DecodeError):
        decode(Scan, raw)


def test_a_row_of_scanners_shares_the_edge_and_each_has_its_own_noise() -> None:
    assert [s.x for s in scanner_row(0.0, 6.0, -2.0)] == [3.0]  # the thesis's one
    assert scanner_count(0.0, 10.0) == 1 and scanner_count(0.0, 10.5) == 2
    row = scanner_row(0.0, 30.0, -2.0)
    assert [s.x for s in row] == [5.0, 15.0, 25.0] and {s.y for s in row} == {-2.0}
    assert all(math.isclose(s.theta, math.pi / 2) for s in row)  # facing the edge
    with pytest.raises(ValueError, match="1 to 16"):
        scanner_row(0.0, 6.0, -2.0, 17)
    a, b = (Laser(Scanner(0.0, 0.0), seed=4, stream=j) for j in (0, 1))
    assert a.scan([(0.0, 2.0)]) != b.scan([(0.0, 2.0)])
    assert Laser(Scanner(0.0, 0.0), seed=4).scan([(0.0, 2.0)]) == \
        Laser(Scanner(0.0, 0.0), seed=4, stream=0).scan([(0.0, 2.0)])
