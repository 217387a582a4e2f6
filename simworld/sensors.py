"""Sensor profiles of the simulated world (pure): ``ideal`` (the default, the world as it
always was) and ``lab``, a world as noisy as the thesis's lab.

``ideal`` is no code at all here: a world without a profile runs exactly the code it
always ran, bit for bit. ``lab`` (``SensorProfile``) adds, each effect a parameter:

- the laser (``LabLaser``): the SICK LMS 2xx's range bias, range noise and millimetre
  resolution; a beam's finite spot, so that a beam across a silhouette edge returns a
  mixed pixel (the energy-weighted mean of what its spot hits, or nothing); beam-angle
  jitter; motion during the sweep (each beam sees the scene at its own time: the mirror
  turns at 75 Hz and the 0.5 degree scan interlaces two turns, so a scan spans 20 ms,
  ending at the scan's time); robots whose outline is an iRobot Create's (a body, a
  slightly prouder front bumper, a mast) instead of one circle; clutter in view (table
  and chair legs) and a person walking among the robots; spurious short returns and
  dropouts;
- the ice and algae sensors (``LabSensing``): an analog reading (the signed distance to
  the boundary the sensor sees) with noise, read ``latency_s`` late, through a
  comparator with a dead band (hysteresis);
- wheel slip (``Slip``): the robot moves a little less than its wheels turned, so
  odometry over-reports distance and turn.

Every random draw comes from a seeded numpy Generator of its own (one per effect and
scanner), so a profile is deterministic and the ideal world's streams are untouched.

Where the figures come from (README, "Sensor profiles", says the same):

- range noise 5 mm (1 sigma) and range bias 15 mm: the LMS 200 data sheet's statistical
  and systematic error in mm mode up to 8 m, as those figures are usually quoted; this
  session's search did not find the LMS 2xx sheet itself (to check on one). SICK's
  knowledge base ("Measurement Errors LMSxxx", support.sick.com) defines the two
  (systematic: from the construction and the temperature, not averaged away) and gives
  +-25 to 30 mm and 6 to 12 mm for the newer LMS1xx/LMS5xx. The bias is taken at its
  bound, the same on every beam, the worst a fixed offset can do.
- 75 Hz mirror, two interlaced turns at 0.5 degree: Player's sicklms200 driver
  documentation (181 readings at 75 Hz at 1 degree, 361 at about 32 Hz at 0.5 degree
  over 500 kBd).
- spot: 13 mm at the front screen growing by 11 mrad, SICK's LMS500 operating
  instructions (8013796, "Beam diameter", SR variant); the LMS 2xx's own divergence was
  not found. The mixed pixel itself (a range between the two objects a spot
  straddles): Ye and Borenstein, "Characterization of a 2-D laser scanner for mobile
  robot obstacle negotiation", ICRA 2002, on the LMS 200.
- ice/algae latency 50 ms: one measuring cycle of a Sharp GP2Y0A21YK-class IR distance
  sensor (about 38 ms) plus the Create's 15 ms sensor stream (OI specification).
- our own assumptions, no public figure: beam-angle jitter, the rates of spurious
  returns and dropouts, the sensors' noise and dead band, the slip, the Create's
  bumper and mast geometry, the clutter's layout and the person's gait.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from simworld.kinematics import integrate_arc
from simworld.laser import Laser, ray_segment

PROFILES = ("ideal", "lab")


@dataclass(frozen=True)
class SensorProfile:
    """The lab profile's parameters; SI units, angles in radians."""

    # --- the laser: SICK LMS 2xx ---------------------------------------------------
    range_noise_m: float = 0.005  # statistical error, 1 sigma (data sheet)
    range_bias_m: float = 0.015  # systematic error, at the data sheet's bound
    range_resolution_m: float = 0.001  # mm mode
    rotation_s: float = 1.0 / 75.0  # one turn of the mirror (75 Hz)
    interlace: int = 2  # 0.5 degree: two turns, the second offset by half a step
    spot_exit_m: float = 0.013  # beam diameter at the front screen
    spot_divergence_rad: float = 0.011  # and its growth per metre of range
    sub_rays: int = 5  # rays across a spot, for mixed pixels
    detect_fraction: float = 0.4  # of a spot's energy that must come back for a return
    beam_jitter_rad: float = 0.0005  # std of each beam's angle
    spurious_prob: float = 0.002  # per beam: a short return anywhere before the target
    dropout_prob: float = 0.002  # per beam: no return at all (reads the maximum)
    # --- the robot's outline at the laser's height: an iRobot Create ---------------
    body_radius_m: float = 0.165  # the back half
    bumper_radius_m: float = 0.172  # the front half, the bumper
    mast_offset_m: float = 0.16  # a mast this far behind the centre, rear left
    mast_angle_rad: float = 2.6  # its bearing from the heading
    mast_radius_m: float = 0.015
    # --- clutter and a person -------------------------------------------------------
    clutter: bool = True  # a table beyond the edge's right end, a chair beyond its left
    person: bool = True  # a person walking a V through the team and back
    person_speed: float = 0.8  # m/s
    leg_radius_m: float = 0.06
    stride_m: float = 0.25  # each foot's swing either side of the body
    step_s: float = 1.1  # a stride's period
    # --- ice and algae sensors --------------------------------------------------------
    sensor_noise_m: float = 0.005  # std of the analog reading, as a distance
    sensor_latency_s: float = 0.05  # the reading is of this long ago
    dead_band_m: float = 0.02  # hysteresis: switches at +- half of it
    # --- wheel slip -------------------------------------------------------------------
    slip_mean: float = 0.01  # fraction of the wheels' distance not travelled
    slip_std: float = 0.01
    turn_slip_mean: float = 0.02  # fraction of the wheels' turn not turned
    turn_slip_std: float = 0.02

    def __post_init__(self) -> None:
        non_negative = ("range_noise_m", "range_resolution_m", "spot_exit_m",
                        "spot_divergence_rad", "beam_jitter_rad", "sensor_noise_m",
                        "sensor_latency_s", "dead_band_m", "slip_std", "turn_slip_std")
        for name in non_negative:
            if not getattr(self, name) >= 0:
                raise ValueError(f"sensor profile: {name} must be >= 0")
        for name in ("spurious_prob", "dropout_prob", "detect_fraction"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"sensor profile: {name} must be in [0, 1]")
        if self.sub_rays < 1 or self.interlace < 1 or not self.rotation_s >= 0:
            raise ValueError("sensor profile: sub_rays and interlace >= 1, rotation_s >= 0")

    @property
    def sweep_s(self) -> float:
        """How long one scan takes, first beam to last."""
        return (self.interlace - 1) * self.rotation_s + 0.5 * self.rotation_s


def profile(name: str) -> SensorProfile | None:
    """The profile of ``--sensors NAME``: None for ``ideal``; ValueError if unknown."""
    if name == "ideal":
        return None
    if name == "lab":
        return SensorProfile()
    raise ValueError(f"unknown sensor profile {name!r}: use one of {', '.join(PROFILES)}")


def beam_offsets(beams: int, rotation_s: float, interlace: int) -> np.ndarray:
    """Each beam's time relative to the scan's (its end), s, all <= 0: beam j is measured
    in turn j % interlace, at its angle's share of the half turn the 180 degrees take."""
    j = np.arange(beams)
    span = (interlace - 1) * rotation_s + 0.5 * rotation_s
    frac = j / max(beams - 1, 1)
    return -span + (j % interlace) * rotation_s + frac * 0.5 * rotation_s


# --- scene: what the laser sees besides the robots ------------------------------------


def clutter_legs(edge_lo: float, edge_hi: float, start_y: float
                 ) -> list[tuple[float, float, float]]:
    """(x, y, radius) of the static legs: a 0.8 x 0.6 m table beyond the edge's right end
    near the start line, a 0.4 m chair beyond its left end by the edge: in view of the
    laser and off every patrol."""
    legs = []
    for dx in (0.6, 1.4):
        for dy in (-0.4, 0.2):
            legs.append((edge_hi + dx, start_y + dy, 0.025))
    for dx in (-1.2, -0.8):
        for y in (-0.2, 0.2):
            legs.append((edge_lo + dx, y, 0.012))
    return legs


@dataclass(frozen=True)
class Walker:
    """A person walking back and forth along a V: from beyond the edge's left end at
    ``y0``, through the middle of the team at ``y1``, to beyond its right end, and back;
    two legs either side of the path, each swinging ``stride_m`` fore and aft."""

    edge_lo: float
    edge_hi: float
    y0: float
    y1: float
    speed: float
    leg_radius: float
    stride: float
    step_s: float
    width: float = 0.09  # each leg's offset from the path

    def _points(self) -> np.ndarray:
        mid = 0.5 * (self.edge_lo + self.edge_hi)
        return np.array([[self.edge_lo - 0.8, self.y0], [mid, self.y1],
                         [self.edge_hi + 0.8, self.y0]])

    def legs(self, t: np.ndarray) -> np.ndarray:
        """Leg centres at times ``t`` (any shape): array of shape (*t.shape, 2, 2)."""
        p = self._points()
        seg = np.diff(p, axis=0)
        lens = np.hypot(seg[:, 0], seg[:, 1])
        total = float(lens.sum())
        s = np.mod(np.asarray(t, dtype=float) * self.speed, 2.0 * total)
        s = np.where(s > total, 2.0 * total - s, s)  # and back
        first = s < lens[0]
        along = np.where(first, s, s - lens[0])
        k = np.where(first, 0, 1)
        u = seg[k] / lens[k][..., None]
        body = p[k] + u * along[..., None]
        back = np.mod(np.asarray(t, dtype=float) * self.speed, 2.0 * total) > total
        u = np.where(back[..., None], -u, u)  # facing the way it walks
        n = np.stack([-u[..., 1], u[..., 0]], axis=-1)
        phase = 2.0 * math.pi * np.asarray(t, dtype=float) / self.step_s
        out = []
        for side, lag in ((1.0, 0.0), (-1.0, math.pi)):
            swing = self.stride * np.sin(phase + lag)
            out.append(body + side * self.width * n + swing[..., None] * u)
        return np.stack(out, axis=-2)


# --- the laser -----------------------------------------------------------------------


@dataclass
class LabLaser:
    """The lab profile's scans from one ``Laser``'s scanner (its pose, walls, seed and
    stream), of robots with a Create's outline moving during the sweep."""

    laser: Laser
    profile: SensorProfile
    clutter: Sequence[tuple[float, float, float]] = ()
    walker: Walker | None = None
    _rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        key = [self.laser.seed, 0x1AB, self.laser.stream]
        self._rng = np.random.default_rng(key)
        s = self.laser.scanner
        self._offsets = beam_offsets(s.beams, self.profile.rotation_s, self.profile.interlace)

    def scan(self, poses: Sequence[tuple[float, float, float]],
             motions: Sequence[tuple[float, float]], dt: float, t: float) -> list[float]:
        """One scan ending at time ``t``: ``poses`` are the robots' true poses at ``t``,
        ``motions`` their true (distance, turn) over the last ``dt`` (each beam sees a
        robot where that motion had it at the beam's time)."""
        p, s, rng = self.profile, self.laser.scanner, self._rng
        beams, m = s.beams, p.sub_rays
        jitter = rng.standard_normal(beams) * p.beam_jitter_rad
        noise = rng.standard_normal(beams) * p.range_noise_m
        spurious = rng.random(beams) < p.spurious_prob
        spurious_at = rng.random(beams)
        dropout = rng.random(beams) < p.dropout_prob
        base = s.theta + s.angles() + jitter  # (beams,)
        sel = self._candidates(base, poses, t)  # only beams that may hit something
        base, tau = base[sel], self._offsets[sel]
        # first the beam's centre ray alone, to size its spot at the range it sees
        centre_hit = self._ranges(base[:, None], tau[:, None], poses, motions, dt, t)[:, 0]
        reach = np.minimum(centre_hit, s.range_max)
        half = 0.5 * (p.spot_exit_m + p.spot_divergence_rad * reach) / np.maximum(reach, 0.05)
        if m > 1:
            spread = np.linspace(-1.0, 1.0, m)
            weights = np.exp(-2.0 * spread * spread)  # a Gaussian spot, 1/e^2 at its rim
        else:
            spread, weights = np.zeros(1), np.ones(1)
        angles = base[:, None] + half[:, None] * spread[None, :]
        sub = np.full((beams, m), s.range_max)
        sub[sel] = self._ranges(angles, np.broadcast_to(tau[:, None], angles.shape), poses,
                                motions, dt, t)
        hit = sub < s.range_max
        w = np.where(hit, weights[None, :], 0.0)
        energy = w.sum(axis=1)
        seen = energy >= p.detect_fraction * weights.sum()
        mixed = (w * np.where(hit, sub, 0.0)).sum(axis=1) / np.maximum(energy, 1e-12)
        r = mixed + p.range_bias_m + noise
        r = np.where(spurious & seen, spurious_at * r, r)
        short = spurious & ~seen  # a spurious return where nothing else was
        r = np.where(short, 0.1 + spurious_at * (s.range_max - 0.1), r)
        ok = (seen | short) & ~dropout
        r = np.where(ok, np.clip(r, 0.0, s.range_max), s.range_max)
        res = p.range_resolution_m
        if res > 0:
            r = np.round(r / res) * res
        return np.round(r, 6).tolist()

    def _candidates(self, angles: np.ndarray, poses: Sequence[tuple[float, float, float]],
                    t: float) -> np.ndarray:
        """Indices of the beams (world ``angles``) that pass near a robot, a leg or a
        wall: within a robot's reach plus what it moves in a sweep and a spot's width."""
        s = self.laser.scanner
        if self.laser.walls:
            return np.arange(angles.size)
        objects = [(x, y, 0.3) for x, y, _ in poses]
        objects += [(x, y, r + 0.05) for x, y, r in self.clutter]
        if self.walker is not None:
            # wherever its legs are during the sweep: body +- stride, width and leg
            reach = self.walker.stride + self.walker.width + self.walker.leg_radius + 0.1
            for x, y in self.walker.legs(np.array(t)).reshape(-1, 2):
                objects.append((float(x), float(y), reach))
        keep = np.zeros(angles.size, dtype=bool)
        for x, y, r in objects:
            d = math.hypot(x - s.x, y - s.y)
            if d - r > s.range_max:
                continue
            bearing = math.atan2(y - s.y, x - s.x)
            width = math.pi if d <= r else math.asin(r / d) + 0.02
            keep |= np.abs(np.angle(np.exp(1j * (angles - bearing)))) <= width
        return np.flatnonzero(keep)

    @np.errstate(invalid="ignore")
    def _ranges(self, angles: np.ndarray, tau: np.ndarray,
                poses: Sequence[tuple[float, float, float]],
                motions: Sequence[tuple[float, float]], dt: float, t: float) -> np.ndarray:
        """Range along every ray (world angle ``angles``, time offset ``tau``, both of
        shape (beams, rays)) to the nearest robot, leg or wall (``range_max`` if none)."""
        p, s = self.profile, self.laser.scanner
        ux, uy = np.cos(angles)[..., None], np.sin(angles)[..., None]  # (B, R, 1)
        out = np.full(angles.shape, np.inf)
        if poses:
            pose = np.asarray(poses, dtype=float)  # (n, 3)
            move = np.asarray(motions, dtype=float)  # (n, 2)
            frac = (tau / dt if dt > 0 else np.zeros_like(tau))[..., None]  # <= 0: back
            cx, cy, ch = _arc_back(pose[:, 0], pose[:, 1], pose[:, 2], move[:, 0] * frac,
                                   move[:, 1] * frac)  # (B, R, n): each robot at each ray's time
            hx, hy = np.cos(ch), np.sin(ch)
            ox, oy = cx - s.x, cy - s.y
            front = _circle(ux, uy, ox, oy, p.bumper_radius_m)
            front = np.where((front * ux - ox) * hx + (front * uy - oy) * hy >= 0.0, front,
                             np.inf)
            rear = _circle(ux, uy, ox, oy, p.body_radius_m)
            rear = np.where((rear * ux - ox) * hx + (rear * uy - oy) * hy < 0.0, rear, np.inf)
            ma = ch + p.mast_angle_rad
            mast = _circle(ux, uy, ox + p.mast_offset_m * np.cos(ma),
                           oy + p.mast_offset_m * np.sin(ma), p.mast_radius_m)
            out = np.minimum(out, np.minimum(np.minimum(front, rear), mast).min(axis=-1))
        if self.clutter:
            c = np.asarray(self.clutter, dtype=float)
            hit = _circle(ux, uy, c[:, 0] - s.x, c[:, 1] - s.y, c[:, 2])
            out = np.minimum(out, hit.min(axis=-1))
        if self.walker is not None:
            legs = self.walker.legs(t + tau)  # (B, R, 2, 2)
            hit = _circle(ux, uy, legs[..., 0] - s.x, legs[..., 1] - s.y, self.walker.leg_radius)
            out = np.minimum(out, hit.min(axis=-1))
        for x0, y0, x1, y1 in self.laser.walls:
            out = np.minimum(out, ray_segment(ux[..., 0], uy[..., 0], x0 - s.x, y0 - s.y,
                                           x1 - x0, y1 - y0))
        return np.minimum(out, s.range_max)


def _arc_back(x: np.ndarray, y: np.ndarray, th: np.ndarray, dist: np.ndarray,
              dth: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses ``dist`` along the arc turning ``dth`` from (x, y, th), arrays broadcast
    together (exact arcs, as ``integrate_arc``; negative values go back along a step)."""
    straight = np.abs(dth) < 1e-9
    safe = np.where(straight, 1.0, dth)
    radius = dist / safe
    end = th + dth
    ax = np.where(straight, x + dist * np.cos(th), x + radius * (np.sin(end) - np.sin(th)))
    ay = np.where(straight, y + dist * np.sin(th), y - radius * (np.cos(end) - np.cos(th)))
    return ax, ay, end


def _circle(ux: np.ndarray, uy: np.ndarray, cx: np.ndarray | float, cy: np.ndarray | float,
            radius: np.ndarray | float) -> np.ndarray:
    """Range along rays (ux, uy) from the origin to circles at (cx, cy) (inf if missed,
    or if the origin is inside), broadcast together."""
    along = ux * cx + uy * cy
    miss2 = np.asarray(cx) ** 2 + np.asarray(cy) ** 2 - along * along
    inside = np.asarray(radius) ** 2 - miss2
    tt = along - np.sqrt(np.maximum(inside, 0.0))
    return np.where((inside >= 0.0) & (along > 0.0) & (tt >= 0.0), tt, np.inf)


# --- ice and algae sensors -------------------------------------------------------------


class LabSensing:
    """Ice and algae readings of n robots through noise, latency and a dead band. The
    analog signal is the signed distance, across the edge, into what the sensor looks
    for (positive inside): for ice, how far the robot is past the local edge; for algae,
    how far inside the algae band above it."""

    def __init__(self, profile: SensorProfile, n: int, seed: int) -> None:
        self.profile = profile
        self._rng = np.random.default_rng([seed, 0x5E45])
        self._state: list[list[bool] | None] = [None] * n

    @staticmethod
    def signals(gmap: object, x: float, y: float) -> tuple[float, float]:
        """(ice, algae) signed distances at (x, y) on a ``GridMap``."""
        m = gmap  # a GridMap; typed loosely to keep this module free of the map's import
        inside = m.edge_lo <= x < m.edge_hi  # type: ignore[attr-defined]
        if not inside:
            return -1.0, -1.0
        edge = float(m.edge_y(x))  # type: ignore[attr-defined]
        depth = float(m.algae_depth(x))  # type: ignore[attr-defined]
        ice = y - edge
        algae = min(y - edge, edge + depth - y) if depth > 0 else -1.0
        return ice, algae

    def read(self, i: int, gmap: object, x: float, y: float) -> tuple[bool, bool]:
        """Robot i's (ice, algae) readings, (x, y) being where it was ``latency_s`` ago."""
        p = self.profile
        ice, algae = self.signals(gmap, x, y)
        noise = self._rng.standard_normal(2) * p.sensor_noise_m
        values = (ice + float(noise[0]), algae + float(noise[1]))
        state = self._state[i]
        if state is None:  # power-up: the comparator starts where the signal is
            state = [v > 0.0 for v in values]
        half = 0.5 * p.dead_band_m
        for k, v in enumerate(values):
            if state[k] and v < -half:
                state[k] = False
            elif not state[k] and v > half:
                state[k] = True
        self._state[i] = state
        return state[0], state[1]


# --- wheel slip -----------------------------------------------------------------------


class Slip:
    """The fraction of each step's wheel distance and turn a robot does not make."""

    def __init__(self, profile: SensorProfile, seed: int) -> None:
        self.profile = profile
        self._rng = np.random.default_rng([seed, 0x511B])

    def draw(self, n: int) -> np.ndarray:
        """(n, 2): each robot's distance and turn slip for one step, in [0, 0.5]."""
        p = self.profile
        z = self._rng.standard_normal((n, 2))
        out = np.stack([p.slip_mean + p.slip_std * z[:, 0],
                        p.turn_slip_mean + p.turn_slip_std * z[:, 1]], axis=1)
        return np.clip(out, 0.0, 0.5)


def pose_back(pose: tuple[float, float, float], motion: tuple[float, float], dt: float,
              back_s: float) -> tuple[float, float, float]:
    """Where a robot at ``pose`` was ``back_s`` seconds ago, its last step of ``dt`` having
    been ``motion`` (distance, turn)."""
    if dt <= 0 or back_s <= 0:
        return pose
    f = -min(back_s, dt) / dt
    return integrate_arc(pose[0], pose[1], pose[2], motion[0] * f, motion[1] * f)


__all__ = ["PROFILES", "LabLaser", "LabSensing", "SensorProfile", "Slip", "Walker",
           "beam_offsets", "clutter_legs", "pose_back", "profile"]
