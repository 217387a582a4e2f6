"""The localizer's pure core on synthetic scans from the simulator's laser model:
blob to centre, assignment of robots passing each other, occlusion, start without a
pose, kidnapping, and the resampler against filterpy's."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.monte_carlo import systematic_resample as filterpy_systematic

from localizer.associate import Recovery, held_wrongly
from localizer.core import (
    FilterConfig,
    Localizer,
    ScanGeometry,
    assign,
    blob_centre,
    measure_centres,
    merge_centres,
    split_blobs,
    systematic_resample,
)
from simworld.laser import Laser, Scanner, box_walls

SCANNER = Scanner(3.0, -2.0)
GEOMETRY = ScanGeometry(SCANNER.x, SCANNER.y, SCANNER.theta, SCANNER.angle_min,
                        SCANNER.angle_step, SCANNER.range_max, SCANNER.beams)


def scan_of(laser: Laser, centres: list[tuple[float, float]]) -> np.ndarray:
    return np.asarray(laser.scan(np.asarray(centres, dtype=float)))


@pytest.mark.parametrize("centre", [(3.0, -1.0), (0.2, -0.3), (5.5, 1.6), (1.0, 1.5)])
def test_lone_robot_centre_within_a_centimetre(centre: tuple[float, float]) -> None:
    errors = []
    for seed in range(40):
        found = measure_centres(scan_of(Laser(SCANNER, seed=seed), [centre]), GEOMETRY,
                                FilterConfig())
        assert found.shape == (1, 2)
        errors.append(math.dist(found[0], centre))
    assert np.mean(errors) < 0.01 and max(errors) < 0.02  # 1 cm range noise, 4 m away


def test_all_blobs_at_once_equal_one_blob_at_a_time() -> None:
    centres = [(0.5, -1.0), (1.5, 0.5), (2.9, 0.0), (3.1, 1.0), (4.5, 1.5), (5.5, -0.5)]
    ranges = scan_of(Laser(SCANNER, seed=9), centres)
    config = FilterConfig()
    one_by_one = [c for b in split_blobs(ranges, GEOMETRY, config.jump_m)
                  if (c := blob_centre(ranges, GEOMETRY, b, config)) is not None]
    assert np.allclose(measure_centres(ranges, GEOMETRY, config), one_by_one, atol=1e-9)


def test_thesis_estimate_alone_is_close_too() -> None:
    laser = Laser(SCANNER, noise_m=0.0)
    found = measure_centres(scan_of(laser, [(1.0, 1.0)]), GEOMETRY, FilterConfig(refine=False))
    assert math.dist(found[0], (1.0, 1.0)) < 0.03  # bearing quantised to 0.5 degrees


def test_walls_are_not_robots_and_robots_hide_what_is_behind() -> None:
    walls = box_walls(-1.0, -2.5, 7.0, 4.0)
    laser = Laser(SCANNER, walls=walls, seed=3)
    ranges = scan_of(laser, [(3.0, 0.0), (3.0, 1.0)])  # the second hides behind the first
    assert (ranges < SCANNER.range_max).all()  # the walls close the view
    found = measure_centres(ranges, GEOMETRY, FilterConfig())
    assert found.shape == (1, 2) and math.dist(found[0], (3.0, 0.0)) < 0.01
    assert len(split_blobs(ranges, GEOMETRY, 0.1)) >= 2


def test_assignment_gates_and_ignores_strangers() -> None:
    predicted = np.array([[1.0, 0.0], [2.0, 0.0]])
    measured = np.array([[2.05, 0.0], [5.0, 5.0], [0.98, 0.01]])
    assert assign(predicted, measured, np.array([True, True]), 0.25).tolist() == [2, 0]
    assert assign(predicted, measured[1:2], np.array([True, True]), 0.25).tolist() == [-1, -1]


def track(localizer: Localizer, laser: Laser, poses: np.ndarray,
          odometry: np.ndarray) -> list[np.ndarray]:
    """Run the filter over a trajectory (poses (T, R, 3), odometry (T, R, 2));
    return the estimates (T, R, 3)."""
    out = []
    for k in range(poses.shape[0]):
        ranges = scan_of(laser, poses[k, :, :2].tolist())
        est = localizer.step(ranges, GEOMETRY, odometry[k, :, 0], odometry[k, :, 1])
        out.append(np.array([[e.x, e.y, e.theta] for e in est]))
    return out


def straight_lines(starts: list[tuple[float, float, float]], speed: float, steps: int,
                   dt: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    poses = np.zeros((steps, len(starts), 3))
    odom = np.zeros((steps, len(starts), 2))
    for r, (x, y, th) in enumerate(starts):
        for k in range(steps):
            d = speed * dt * k
            poses[k, r] = (x + d * math.cos(th), y + d * math.sin(th), th)
            odom[k, r] = (speed * dt if k else 0.0, 0.0)
    return poses, odom


def test_starts_without_a_pose_and_learns_the_heading_from_motion() -> None:
    poses, odom = straight_lines([(1.0, -1.0, 0.5 * math.pi), (4.0, -1.0, 0.5 * math.pi)],
                                 0.3, 60)
    loc = Localizer(2, seed=2)
    est = track(loc, Laser(SCANNER, seed=2), poses, odom)
    for r in range(2):
        assert math.dist(est[0][r, :2], poses[0, r, :2]) < 0.05  # robots in edge order
        assert math.dist(est[-1][r, :2], poses[-1, r, :2]) < 0.03
        assert abs(est[-1][r, 2] - poses[-1, r, 2]) < 0.15


def test_two_robots_passing_each_other_keep_their_identities() -> None:
    # robot 0 drives +x, robot 1 drives -x, 0.5 m apart across: they pass at x = 3
    poses, odom = straight_lines([(1.5, 0.0, 0.0), (4.5, 0.5, math.pi)], 0.5, 60)
    loc = Localizer(2, seed=4)
    est = track(loc, Laser(SCANNER, seed=4), poses, odom)
    errors = np.array([np.hypot(*(e[:, :2] - p[:, :2]).T) for e, p in zip(est, poses,
                                                                          strict=True)])
    assert errors[5:].max() < 0.05  # never swapped (a swap is a 3 m error at the end)


def test_occluded_robot_keeps_its_estimate_by_prediction() -> None:
    # robot 1 drives -x along y = 1.2 behind robot 0, parked at (3, 0): hidden for a while
    steps = 40
    poses = np.zeros((steps, 2, 3))
    odom = np.zeros((steps, 2, 2))
    poses[:, 0] = (3.0, 0.0, 0.5 * math.pi)
    for k in range(steps):
        poses[k, 1] = (4.0 - 0.05 * k, 1.2, math.pi)
        odom[k, 1] = (0.05 if k else 0.0, 0.0)
    laser = Laser(SCANNER, seed=5)
    loc = Localizer(2, seed=5)
    hidden = []
    errors = []
    for k in range(steps):
        ranges = scan_of(laser, poses[k, :, :2].tolist())
        est = loc.step(ranges, GEOMETRY, odom[k, :, 0], odom[k, :, 1])
        if not est[1].measured:
            hidden.append(k)
        errors.append(math.dist((est[1].x, est[1].y), poses[k, 1, :2]))
    assert len(hidden) >= 5  # it really was hidden for several scans
    assert max(errors[k] for k in hidden) < 0.05
    assert max(errors[5:]) < 0.05


def test_kidnapped_robot_is_found_again() -> None:
    poses, odom = straight_lines([(1.0, -1.0, 0.5 * math.pi), (4.5, -1.0, 0.5 * math.pi)],
                                 0.2, 80)
    poses[40:, 1, 0] -= 1.0  # carried 1 m along the edge at scan 40, odometry unaware
    loc = Localizer(2, seed=6)
    est = track(loc, Laser(SCANNER, seed=6), poses, odom)
    err = [math.dist(e[1, :2], p[1, :2]) for e, p in zip(est, poses, strict=True)]
    assert err[39] < 0.05 and err[40] > 0.5
    back = next(k for k in range(40, 80) if all(e < 0.05 for e in err[k:]))
    assert back - 40 <= 20
    assert loc.reseeded >= 3  # two at the start, one after the kidnapping


def test_vectorised_resampler_matches_filterpy() -> None:
    rng = np.random.default_rng(7)
    weights = rng.random((4, 500)) ** 8
    weights /= weights.sum(axis=1, keepdims=True)
    offsets = np.empty(4)
    expected = []
    for r in range(4):
        np.random.seed(100 + r)
        offsets[r] = np.random.random()
        np.random.seed(100 + r)
        expected.append(filterpy_systematic(weights[r]))
    got = systematic_resample(weights, offsets)
    assert np.array_equal(got, np.asarray(expected))


def test_a_robot_two_scanners_see_is_one_centre() -> None:
    a = np.array([[1.0, 0.0], [2.0, 1.0]])
    b = np.array([[2.01, 1.0], [9.0, 0.5], [1.02, 0.0]])  # robot 1, a third, robot 0
    merged = merge_centres([a, b], 0.17)
    assert merged.shape == (3, 2)
    assert np.allclose(merged, [[1.01, 0.0], [2.005, 1.0], [9.0, 0.5]])
    assert merge_centres([a], 0.17) is a  # one scanner: as measured
    close = np.array([[1.0, 0.0], [1.1, 0.0]])  # one scan's blobs stay its own
    assert merge_centres([close, np.empty((0, 2))], 0.17).shape == (2, 2)


def test_a_row_of_scanners_tracks_a_team_one_scanner_cannot_see() -> None:
    """Four robots along 20 m: from the middle the ends are beyond the LMS's 8 m; a
    row of two sees every robot, and where both see one it is still one robot."""
    starts = [(x, -1.0, 0.5 * math.pi) for x in (0.5, 7.0, 13.0, 19.5)]
    poses, odom = straight_lines(starts, 0.3, 60)
    row = [Scanner(5.0, -2.0), Scanner(15.0, -2.0)]
    lasers = [Laser(s, seed=5, stream=j) for j, s in enumerate(row)]
    geometries = [ScanGeometry(s.x, s.y, s.theta, s.angle_min, s.angle_step, s.range_max,
                               s.beams) for s in row]
    loc = Localizer(4, seed=5)
    for k in range(poses.shape[0]):
        scans = [(scan_of(laser, poses[k, :, :2].tolist()), g)
                 for laser, g in zip(lasers, geometries, strict=True)]
        est = loc.step_scans(scans, odom[k, :, 0], odom[k, :, 1])
    for r, e in enumerate(est):
        assert math.dist((e.x, e.y), poses[-1, r, :2]) < 0.03 and not e.lost
    assert loc.reseeded == 4  # each robot seeded once, none from a duplicate centre
    alone = Localizer(4, seed=5)
    middle = Scanner(10.0, -2.0)
    laser = Laser(middle, seed=5)
    geometry = ScanGeometry(middle.x, middle.y, middle.theta, middle.angle_min,
                            middle.angle_step, middle.range_max, middle.beams)
    for k in range(poses.shape[0]):
        est = alone.step(scan_of(laser, poses[k, :, :2].tolist()), geometry, odom[k, :, 0],
                         odom[k, :, 1])
    assert sum(e.lost for e in est) >= 2  # the ends were never seen


def _run_team(loc: Localizer, laser: Laser, poses: np.ndarray, odom: np.ndarray
              ) -> np.ndarray:
    """Errors (T, R) of the filter's estimates over a trajectory (see ``track``)."""
    est = track(loc, laser, poses, odom)
    return np.array([np.hypot(*(e[:, :2] - p[:, :2]).T) for e, p in zip(est, poses,
                                                                          strict=True)])


def _parked_joiner_scene(steps: int, wait: int, first_move: float
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Poses and odometry of ``btrack sim --robots 3 --fault join:3@...``'s start: robots
    0 and 2 drive up from the start line, robot 3 stands parked in front of the scanner
    and robot 1 behind it, which drives ``first_move`` at the first tick, waits until
    scan ``wait`` and then drives off up and left."""
    poses = np.zeros((steps, 4, 3))
    odom = np.zeros((steps, 4, 2))
    poses[:, 3] = (3.0, -1.5, 0.5 * math.pi)  # parked, never driven
    for r, x in ((0, 0.05), (2, 4.05)):
        for k in range(steps):
            poses[k, r] = (x, -1.0 + 0.02 * k, 0.5 * math.pi)
            odom[k, r] = (0.02 if k else 0.0, 0.0)
    heading = 0.75 * math.pi
    for k in range(steps):
        d = 0.03 * max(0, k - wait)
        poses[k, 1] = (2.8 + d * math.cos(heading), -1.0 + first_move + d * math.sin(heading),
                       heading)
        odom[k, 1] = (0.03 if k > wait else 0.0, 0.0)
    poses[0, 1, 1] = -1.0
    odom[1, 1, 0] += first_move
    return poses, odom


def test_a_robot_parked_in_view_is_not_taken_for_a_driving_one() -> None:
    """btrack sim --robots 3 --fault join:3@200 with pf: robot 1 starts hidden behind
    the joiner parked in front of it, so at the start robot 1's filter takes the
    joiner's blob. Once robot 1 drives, a blob that stands still is not it: it is
    found where it comes out, and the joiner's filter gets the parked blob."""
    poses, odom = _parked_joiner_scene(120, wait=30, first_move=0.0)
    loc = Localizer(4, seed=8)
    errors = _run_team(loc, Laser(SCANNER, seed=8), poses, odom)
    assert errors[5, 1] > 0.3  # hidden at the start: it took the joiner's blob
    assert (errors[-30:, :] < 0.05).all()  # each robot found, the joiner on its spot
    assert (errors[:, 0] < 0.05).all() and (errors[:, 2] < 0.05).all()


def test_a_robot_that_drove_is_not_the_parked_blob_it_took_at_the_start() -> None:
    """As ``btrack sim --robots 3 --fault join:3@200`` starts: robot 1, hidden behind the
    joiner parked in front of it, takes the joiner's blob on the first scan; it drives
    2.8 cm at the first tick and then waits (its phase is ahead). A blob that stood
    still is no robot that drove: robot 1 is released within a few scans (lost, as a
    robot hidden is), and the joiner takes its parked blob; robot 1 takes no blob that
    stands still, and is found once it drives out where the laser sees it."""
    steps = 90
    poses, odom = _parked_joiner_scene(steps, wait=50, first_move=0.028)
    loc = Localizer(4, seed=8)
    laser = Laser(SCANNER, seed=8)
    est, lost = [], []
    for k in range(steps):
        out = loc.step(scan_of(laser, poses[k, :, :2].tolist()), GEOMETRY, odom[k, :, 0],
                       odom[k, :, 1])
        est.append([(e.x, e.y) for e in out])
        lost.append([e.lost for e in out])
    err = np.hypot(*(np.array(est) - poses[:, :, :2]).transpose(2, 0, 1))  # (T, R)
    assert err[0, 1] > 0.3  # it did take the joiner's blob
    assert loc.released == 1
    assert (err[4:, 3] < 0.01).all()  # the joiner on its parked spot from the fourth scan
    assert all(row[1] for row in lost[10:45])  # robot 1 lost while hidden, not on a blob
    assert (err[-20:, 1] < 0.05).all()  # found once it drives out
    assert (err[:, 0] < 0.05).all() and (err[:, 2] < 0.05).all()


def test_a_blob_held_is_released_only_when_it_stood_while_the_robot_drove() -> None:
    rules = Recovery()
    still = [np.array([[1.0, 0.0], [2.0, 0.0]])] * rules.held_scans
    moving = [np.array([[1.0, 0.0], [2.0, 0.01 * k]]) for k in range(rules.held_scans)]
    match = np.array([0, 1])
    drove = np.array([0.03, 0.03])
    assert held_wrongly(match, still[-1], still, drove, rules).tolist() == [True, True]
    assert held_wrongly(match, moving[-1], moving, drove, rules).tolist() == [True, False]
    assert not held_wrongly(match, still[-1], still, np.array([0.01, 0.0]), rules).any()
    assert not held_wrongly(np.array([-1, -1]), still[-1], still, drove, rules).any()
    assert not held_wrongly(match, still[-1], still[:2], drove, rules).any()  # too soon


def test_an_occluded_robot_does_not_jump_to_a_blob_across_the_scene() -> None:
    """Robot 0 drives in front of robot 1 and stops there, hiding it; robot 2 drives
    with odometry that says nothing, so its filter keeps falling behind and its blob
    is free again and again. Robot 1 must not re-seed there: the blob is metres from
    its prediction, and robot 2's filter is the nearer claimant."""
    steps = 60
    poses = np.zeros((steps, 3, 3))
    odom = np.zeros((steps, 3, 2))
    for k in range(steps):
        poses[k, 0] = (1.0 + 0.1 * min(k, 20), -1.0, 0.0)  # then stands in the way
        odom[k, 0] = (0.1 if 0 < k <= 20 else 0.0, 0.0)
        poses[k, 1] = (3.0, 1.0, 0.5 * math.pi)
        poses[k, 2] = (5.5, 0.04 * k, 0.5 * math.pi)  # its odometry is silent
    loc = Localizer(3, seed=9)
    errors = _run_team(loc, Laser(SCANNER, seed=9), poses, odom)
    assert (errors[:, 0] < 0.05).all()
    assert errors[:, 1].max() < 0.1  # hidden, it stays where it was last seen
    assert errors[-1, 2] < 0.3  # robot 2's filter caught up by re-seeding


def test_a_blob_faster_than_a_robot_drives_re_seeds_no_lost_robot() -> None:
    """A person walking through the team at 0.8 m/s, legs close enough to look like one
    robot, took an occluded robot's track in the lab suite (5 m off for 8 s). A free
    blob followed back over the recent scans that moved faster than a Create can is no
    robot; a slow one is, and one that just came into view cannot be told."""
    from localizer.associate import Recovery, fast_blobs, recovery

    scans = 10
    walker = [np.array([[1.0 + 0.08 * k, 0.5], [4.0 + 0.03 * k, 1.0]]) for k in range(scans)]
    now = np.vstack([walker[-1], [[2.5, 1.5]]])  # and one just come into view
    recent = [*walker[:-1], now]
    fast = fast_blobs(now, recent, follow_m=0.25, speed_m_s=0.6, scan_s=0.1)
    assert fast.tolist() == [True, False, False]
    assert not fast_blobs(now, recent, 0.25, 0.9, 0.1).any()  # 0.8 m/s is under 0.9
    rules = Recovery(top_speed_m_s=0.6)
    started, missed = np.array([True]), np.array([30])
    predicted = np.array([[1.5, 0.4]])  # nearest the walker: 0.3 m, the others 2 m on
    used = np.zeros(3, dtype=bool)
    moved = np.array([False])
    assert recovery(now, used, predicted, started, missed, None, moved, rules) == [(0, 0)]
    taken = recovery(now, used, predicted, started, missed, None, moved, rules, fast)
    assert taken and taken[0][1] != 0


def test_a_hidden_robot_that_stands_takes_no_moving_blob_beyond_its_drive() -> None:
    """In the lab suite a robot stood hidden at the deep end of its leg for 4 s while
    the person turned round 1.9 m away, slowly: it took the person's legs. A moving blob
    is a robot whose wheels stood (failed wheels) only near its prediction, as far as it
    drives in the scans it takes to be lost; a blob that stands still may be it (carried
    off, set down)."""
    from localizer.associate import Recovery, recovery

    rules = Recovery(top_speed_m_s=0.6)
    centres = np.array([[-0.1, -0.3]])
    predicted = np.array([[0.08, 1.57]])  # 1.9 m off
    args = (np.zeros(1, dtype=bool), predicted, np.array([True]), np.array([39]))
    moving, standing = np.array([False]), np.array([True])
    odometry_stood = np.array([False])
    assert recovery(centres, *args, moving, odometry_stood, rules, None, 0.1) == []
    assert recovery(centres, *args, standing, odometry_stood, rules, None, 0.1) == [(0, 0)]
    # without the top speed (the ideal laser's rules) as before: taken
    assert recovery(centres, *args, moving, odometry_stood, Recovery(), None, 0.1) == [(0, 0)]
