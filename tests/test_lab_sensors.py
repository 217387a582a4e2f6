"""The lab sensor profile (simworld/sensors.py) effect by effect, each against a scene
whose answer is known, and the localizer's lab configuration on its scans."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from localizer.core import FilterConfig, ScanGeometry
from localizer.measure import measure_blobs, median3, sweep_offsets
from simworld.laser import Laser, Scanner
from simworld.maps import builtin_map
from simworld.sensors import (
    LabLaser,
    LabSensing,
    SensorProfile,
    Slip,
    Walker,
    beam_offsets,
    clutter_legs,
    profile,
)
from simworld.world import World

SCANNER = Scanner(3.0, -2.0)
MIDDLE = 180  # the beam straight ahead
# every effect off: a circle of 0.17 m, exact ranges to the micrometre, one ray a beam
BARE = SensorProfile(range_noise_m=0.0, range_bias_m=0.0, range_resolution_m=0.0,
                     rotation_s=0.0, sub_rays=1, detect_fraction=1.0, beam_jitter_rad=0.0,
                     spurious_prob=0.0, dropout_prob=0.0, body_radius_m=0.17,
                     bumper_radius_m=0.17, mast_radius_m=0.0, clutter=False, person=False)


def lab_laser(p: SensorProfile, **kw: object) -> LabLaser:
    return LabLaser(Laser(SCANNER, seed=1), p, **kw)  # type: ignore[arg-type]


def geometry() -> ScanGeometry:
    s = SCANNER
    return ScanGeometry(s.x, s.y, s.theta, s.angle_min, s.angle_step, s.range_max, s.beams)


def test_profiles_by_name() -> None:
    assert profile("ideal") is None  # the ideal world runs no profile code at all
    assert profile("lab") == SensorProfile()
    with pytest.raises(ValueError, match="unknown sensor profile"):
        profile("field")
    with pytest.raises(ValueError, match="spurious_prob"):
        SensorProfile(spurious_prob=2.0)


def test_bare_profile_is_the_ideal_laser_without_noise() -> None:
    centres = [(3.0, 0.0), (1.5, 1.0)]
    ideal = Laser(SCANNER, noise_m=0.0).exact(np.array(centres))
    bare = lab_laser(BARE).scan([(x, y, 1.0) for x, y in centres], [(0.0, 0.0)] * 2, 0.1, 0.0)
    assert np.allclose(bare, ideal, atol=1e-6)


def test_range_bias_and_noise_as_configured() -> None:
    biased = lab_laser(dataclasses.replace(BARE, range_bias_m=0.015))
    r = biased.scan([(3.0, 0.0, 0.0)], [(0.0, 0.0)], 0.1, 0.0)
    assert r[MIDDLE] == pytest.approx(2.0 - 0.17 + 0.015, abs=1e-6)
    noisy = lab_laser(dataclasses.replace(BARE, range_noise_m=0.005))
    hits = []
    for k in range(200):
        hits.append(noisy.scan([(3.0, 0.0, 0.0)], [(0.0, 0.0)], 0.1, 0.1 * k)[MIDDLE])
    assert np.std(hits) == pytest.approx(0.005, rel=0.2)
    assert np.mean(hits) == pytest.approx(1.83, abs=0.002)


def test_seeded_and_deterministic() -> None:
    lab = SensorProfile()
    poses, moves = [(3.0, 0.0, 1.0), (1.0, 1.0, 0.0)], [(0.04, 0.01), (0.0, 0.0)]
    a = lab_laser(lab, walker=None).scan(poses, moves, 0.1, 3.0)
    b = lab_laser(lab, walker=None).scan(poses, moves, 0.1, 3.0)
    c = LabLaser(Laser(SCANNER, seed=1, stream=1), lab).scan(poses, moves, 0.1, 3.0)
    assert a == b and a != c  # the same seed, the same scan; a scanner of its own, its own


def test_create_outline_bumper_in_front_body_behind() -> None:
    p = dataclasses.replace(BARE, body_radius_m=0.165, bumper_radius_m=0.172)
    laser = lab_laser(p)
    facing = laser.scan([(3.0, 0.0, -math.pi / 2)], [(0.0, 0.0)], 0.1, 0.0)[MIDDLE]
    away = laser.scan([(3.0, 0.0, math.pi / 2)], [(0.0, 0.0)], 0.1, 0.0)[MIDDLE]
    assert facing == pytest.approx(2.0 - 0.172, abs=1e-6)
    assert away == pytest.approx(2.0 - 0.165, abs=1e-6)
    mast = dataclasses.replace(p, mast_radius_m=0.015, mast_offset_m=0.16, mast_angle_rad=math.pi)
    seen = lab_laser(mast).scan([(3.0, 0.0, math.pi / 2)], [(0.0, 0.0)], 0.1, 0.0)[MIDDLE]
    assert seen == pytest.approx(2.0 - 0.175, abs=1e-6)  # the mast stands proud of the body


def test_mixed_pixel_between_a_robot_and_what_is_behind_it() -> None:
    p = dataclasses.replace(BARE, sub_rays=5, detect_fraction=0.4, spot_exit_m=0.013,
                            spot_divergence_rad=0.011)
    near, far = (3.0, 0.0), (3.2, 1.0)  # a robot, and another behind its right edge
    r = np.array(lab_laser(p).scan([(*near, 0.0), (*far, 0.0)], [(0.0, 0.0)] * 2, 0.1, 0.0))
    ideal = Laser(SCANNER, noise_m=0.0).exact(np.array([near, far]))
    between = (r > ideal.min() + 0.05) & (r < 8.0) & (np.abs(r - ideal) > 0.05)
    assert between.any()  # a return that is neither robot's surface


def test_motion_during_the_sweep() -> None:
    offsets = beam_offsets(361, 1.0 / 75.0, 2)
    assert offsets.max() == pytest.approx(0.0, abs=1e-4) and offsets.min() == pytest.approx(-0.02)
    assert np.allclose(offsets, sweep_offsets(361, 1.0 / 75.0, 2))  # the localizer's own
    p = dataclasses.replace(BARE, rotation_s=1.0 / 75.0, interlace=2)
    laser = lab_laser(p)
    still = np.array(laser.scan([(3.0, 0.0, 0.0)], [(0.0, 0.0)], 0.1, 0.0))
    moving = np.array(laser.scan([(3.0, 0.0, 0.0)], [(0.05, 0.0)], 0.1, 0.0))  # 0.5 m/s along x
    hit_still, hit_moving = np.flatnonzero(still < 8), np.flatnonzero(moving < 8)
    # earlier beams saw it up to 1 cm back (to the right, lower beam indices)
    assert hit_moving.min() <= hit_still.min() and not np.array_equal(still, moving)


def test_spurious_returns_and_dropouts_at_their_rates() -> None:
    p = dataclasses.replace(BARE, spurious_prob=0.05, dropout_prob=0.05)
    laser = lab_laser(p)
    exact = np.array(lab_laser(BARE).scan([(3.0, 0.0, 0.0)], [(0.0, 0.0)], 0.1, 0.0))
    short = dropped = 0
    scans = 40
    for k in range(scans):
        r = np.array(laser.scan([(3.0, 0.0, 0.0)], [(0.0, 0.0)], 0.1, 0.1 * k))
        short += int((r < exact - 0.01).sum())
        dropped += int(((exact < 8.0) & (r >= 8.0)).sum())
    beams = 361 * scans
    assert 0.03 < short / beams < 0.07  # 5 % short (of those, 5 % dropped again)
    hit_beams = int((exact < 8.0).sum()) * scans
    assert 0.02 < dropped / hit_beams < 0.09


def test_clutter_and_a_walking_person_in_view() -> None:
    legs = clutter_legs(0.0, 6.0, -1.0)
    assert len(legs) == 8 and all(x < 0.0 or x > 6.0 for x, _, _ in legs)  # off the edge
    walker = Walker(0.0, 6.0, -0.6, 0.9, 0.8, 0.06, 0.25, 1.1)
    a, b = walker.legs(np.array(0.0)), walker.legs(np.array(5.0))
    assert a.shape == (2, 2) and np.hypot(*(b.mean(axis=0) - a.mean(axis=0))) > 2.0
    assert 0.1 < float(np.hypot(*(a[0] - a[1]))) < 0.6  # two legs, a stride apart at most
    p = dataclasses.replace(BARE, person=True)
    r = np.array(lab_laser(p, walker=walker).scan([], [], 0.1, 5.0))
    assert (r < 8.0).any()


def test_ice_sensor_dead_band_and_latency() -> None:
    gmap = builtin_map("no-algae")
    quiet = dataclasses.replace(SensorProfile(), sensor_noise_m=0.0, dead_band_m=0.02)
    sensing = LabSensing(quiet, 1, seed=1)
    x = 1.0
    assert sensing.read(0, gmap, x, -0.5) == (False, False)
    assert sensing.read(0, gmap, x, 0.005)[0] is False  # inside the band: no switch yet
    assert sensing.read(0, gmap, x, 0.015)[0] is True
    assert sensing.read(0, gmap, x, -0.005)[0] is True  # and no switch back inside it
    assert sensing.read(0, gmap, x, -0.015)[0] is False
    world = World(gmap, 1, seed=1)
    world.step({0: (0.5, 0.0)}, 0.1)
    back = world.truth_back(0, 0.05, 0.1)
    assert back[1] == pytest.approx(world.truth(0)[1] - 0.025)  # 50 ms at 0.5 m/s


def test_wheel_slip_odometry_over_reports() -> None:
    gmap = builtin_map("no-algae")
    world = World(gmap, 1, seed=1, odom_noise=0.0, slip=Slip(SensorProfile(), seed=1))
    y0 = world.truth(0)[1]
    wheels = 0.0
    for _ in range(50):
        world.step({0: (0.2, 0.0)}, 0.1)
        wheels += world.sense(0).odom_dist_m
    travelled = world.truth(0)[1] - y0
    assert wheels == pytest.approx(1.0) and 0.97 < travelled / wheels < 0.999


def test_no_slip_world_is_unchanged() -> None:
    gmap = builtin_map("half-algae")
    a, b = World(gmap, 3, seed=4), World(gmap, 3, seed=4, slip=None)
    for _ in range(20):
        cmds = {i: (0.3, 0.1 * i) for i in range(3)}
        a.step(cmds, 0.1)
        b.step(cmds, 0.1)
    assert [a.truth(i) for i in range(3)] == [b.truth(i) for i in range(3)]


def test_localizer_lab_blobs_robot_full_leg_not_spike_gone() -> None:
    config = FilterConfig.lab()
    lab = SensorProfile(clutter=False, person=False)
    r = np.array(lab_laser(lab).scan([(3.0, 0.0, math.pi / 2)], [(0.0, 0.0)], 0.1, 0.0))
    blobs = measure_blobs(r, geometry(), config)
    assert blobs.centres.shape == (1, 2) and bool(blobs.full[0])
    # the bias (15 mm) along the line of sight is all that is left
    assert np.hypot(*(blobs.centres[0] - (3.0, 0.0))) < 0.025
    assert -0.02 <= float(blobs.tau[0]) <= 0.0
    legs = dataclasses.replace(lab, person=True)
    walker = Walker(2.0, 4.0, 0.0, 0.0, 0.0, 0.06, 0.0, 1.1)  # standing at (3, 0)
    r = np.array(lab_laser(legs, walker=walker).scan([], [], 0.1, 0.0))
    assert not measure_blobs(r, geometry(), config).full.any()  # a leg never starts a track
    spiky = np.full(361, 8.0)
    spiky[100:110] = 3.0
    spiky[105] = 0.7
    assert median3(spiky)[105] == 3.0 and median3(spiky)[99] == 8.0
