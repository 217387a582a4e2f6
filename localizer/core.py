"""The localizer's pure core: laser scans -> robot centres -> one particle filter per robot.

Thesis chapter 5 (the particle filter) and section 6.1.5 (laser localisation): laser
range finders behind the team see the robots as arcs of circles; each robot's odometry
drives its particle filter's prediction, and the centre measured from the scans
weights the particles.

Laid out as nav2's AMCL is: the measurement (``localizer.measure``: scan -> blobs ->
centres), the data association (``localizer.associate``: which centre is which
robot's, which free blob a lost robot takes), and the filter here, given its motion
and sensor models as objects (``localizer.models``). The steps of
``Localizer.step_scans`` (one tick, one scan per scanner):

1. Predict: every robot's particles by the motion model (``OdometryMotion``, eq. 5.2:
   noise that grows with the distance and turn of the period).
2. Measure: each scan's robot centres (``measure_centres``: the nearest return of a
   blob plus the robot radius along its bearing, thesis 6.1.5, refined by a circle
   fit), one per robot across the scanners (``merge_centres``).
3. Associate: centres to the robots' predicted positions by minimum total squared
   distance, each pair gated at ``gate_m`` (``assign``); a blob that fits no robot is
   ignored, a robot without one (occluded) keeps its prediction.
4. Update: the sensor model's likelihood of the measured centre (``CentreSensor``,
   eq. 5.3), and systematic resampling (the thesis's correction step) when the
   effective sample size 1 / sum(w^2) falls below ``resample_below`` * N.
5. Recovery: the filters start with no pose (particles drawn over the scanners'
   fields of view); on the first scan the robots take the blobs in the order of the
   edge (robot 0 leftmost), which is the order of the team's initial segments. A
   robot whose filter has had no measurement for ``lost_after`` scans is re-seeded
   on a blob no robot took (a kidnapped robot, or one that was hidden): the nearest
   claimant first, each within a reach that grows with the scans it has been lost,
   and never on a blob whose motion its odometry contradicts (a blob standing
   still is no robot that drove: a robot parked in view, waiting to join, is not
   taken for a driving one that was hidden behind it at the start). A robot that
   took such a blob on the first scan lets it go as soon as its wheels drive while
   the blob stands (``held_wrongly``), and is lost until a moving blob is its.

Heading is never measured: it comes from odometry and from which headings carry
the particles to where the scans see the robot.

No I/O, no threads, no clock: time and odometry come in as arguments; the random
numbers come from a seeded numpy Generator owned by the ``Localizer``.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from agent.phase import wrap_pi_array
from localizer.associate import (
    Recovery,
    assign,
    fast_blobs,
    held_wrongly,
    recovery,
    still_blobs,
)
from localizer.measure import (  # noqa: F401  (the measurement's API, re-exported)
    Blobs,
    ScanGeometry,
    blob_centre,
    blob_points,
    blob_spans,
    fit_circle,
    measure_blobs,
    measure_centres,
    merge_blobs,
    merge_centres,
    nearest_return_centre,
    split_blobs,
)
from localizer.models import CentreSensor, OdometryMotion


@dataclass(frozen=True)
class FilterConfig:
    """Localizer parameters; SI units, angles in radians."""

    particles: int = 1000
    radius_m: float = 0.17  # robot radius (iRobot Create)
    meas_std_m: float = 0.02  # std of a measured centre, per axis (likelihood)
    motion: OdometryMotion = field(default_factory=OdometryMotion)  # the odometry's noise
    resample_below: float = 0.5  # resample when N_eff < this fraction of N
    jitter_m: float = 0.001  # roughening after resampling, per axis
    jitter_rad: float = 0.005
    jump_m: float = 0.10  # a gap between returns larger than this splits blobs
    min_returns: int = 3  # fewer returns than this: not a robot (nor a useful arc)
    width_margin_m: float = 0.06  # a blob wider than 2 r + this is not a robot
    fit_rms_m: float = 0.03  # a blob whose circle fit is worse than this is not a robot
    gate_m: float = 0.25  # a centre farther than this from a prediction is not that robot
    recovery: Recovery = field(default_factory=Recovery)  # which free blob a lost robot takes
    reseed_std_m: float = 0.02
    reseed_heading_std_rad: float = 0.2  # around the filter's own heading
    reseed_uniform_frac: float = 0.2  # of re-seeded particles with any heading
    refine: bool = True  # fit a circle to the blob after the thesis's estimate
    # --- for a real LMS (``FilterConfig.lab()``); the defaults are the ideal scan's ------
    blobs: bool = False  # measure with ``measure_blobs`` (the fields below); else as always
    median3: bool = False  # median-filter each scan over three beams (spikes, dropouts)
    trim_edges: int = 0  # returns dropped at each end of a blob (mixed pixels)
    full_chord_m: float = 0.0  # a blob this wide saw a robot whole: only such start tracks
    partial_gate_m: float = 0.25  # a narrower blob is a robot's only this close to it
    rotation_s: float = 0.0  # the LMS's mirror turn, s (0: every beam at the scan's time)
    interlace: int = 1  # turns per scan (2 at 0.5 degree)
    # the robot's outline, when it is not the circle of ``radius_m``: a body of
    # ``body_radius_m`` behind, a bumper of ``bumper_radius_m`` in front (0: a circle)
    body_radius_m: float = 0.0
    bumper_radius_m: float = 0.0

    def __post_init__(self) -> None:
        if self.particles < 2:
            raise ValueError("need at least two particles")
        if self.radius_m <= 0 or self.meas_std_m <= 0 or self.gate_m <= 0:
            raise ValueError("radius, measurement std and gate must be positive")
        if not 0.0 < self.resample_below <= 1.0:
            raise ValueError("resample_below must be in (0, 1]")
        if self.trim_edges < 0 or self.interlace < 1 or self.rotation_s < 0:
            raise ValueError("trim_edges >= 0, interlace >= 1 and rotation_s >= 0")

    @classmethod
    def lab(cls, **overrides: object) -> FilterConfig:
        """The configuration for a real SICK LMS 2xx (``btrack sim --sensors lab``): scans
        median-filtered, a blob's edge returns (mixed pixels) left out of the fit, a tighter
        fit, partial blobs only close to a robot's prediction and never starting a track
        (a person's leg, a table leg), no lost robot re-seeded on a blob moving faster
        than a Create drives (a person walking), and each centre moved to the scan's time by the
        robot's odometry (the LMS's 75 Hz mirror, two interlaced turns at 0.5 degree:
        Player's sicklms200 documentation)."""
        values: dict[str, object] = dict(blobs=True, median3=True, trim_edges=1,
                                          fit_rms_m=0.012, full_chord_m=0.22,
                                          partial_gate_m=0.06, rotation_s=1.0 / 75.0,
                                          interlace=2, body_radius_m=0.165,
                                          bumper_radius_m=0.172,
                                          # held_moved_m 0: a robot released from a parked
                                          # robot's blob and lost for long took a walking
                                          # person's legs when it drove out (see README)
                                          recovery=Recovery(top_speed_m_s=LAB_TOP_SPEED_M_S,
                                                            held_moved_m=0.0))
        values.update(overrides)
        return cls(**values)  # type: ignore[arg-type]


LAB_TOP_SPEED_M_S = 0.6  # a Create's top speed (0.5 m/s, the Open Interface's) and a margin


@dataclass(frozen=True)
class Estimate:
    """One robot's pose estimate after a scan."""

    x: float
    y: float
    theta: float
    var_x: float
    var_y: float
    var_theta: float
    measured: bool  # a blob was assigned to this robot in this scan
    lost: bool  # no pose yet, or no measurement for ``Recovery.lost_after`` scans


# --- the particle filter --------------------------------------------------------------


def systematic_resample(weights: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Systematic resampling of every row of ``weights`` (R, N) at once: the algorithm
    of ``filterpy.monte_carlo.systematic_resample`` (one random offset per row,
    positions (offset + i) / N), vectorised with one ``searchsorted``; index for
    index the same as filterpy's for the same offset (tests/test_localizer_core.py)."""
    rows, n = weights.shape
    cum = np.cumsum(weights, axis=1)
    cum /= cum[:, -1:]
    cum[:, -1] = 1.0 + 1e-12  # a position can never fall past the last particle
    shift = np.arange(rows, dtype=float)[:, None] * 2.0
    positions = (offsets[:, None] + np.arange(n)[None, :]) / n
    flat = np.searchsorted((cum + shift).ravel(), (positions + shift).ravel(), side="right")
    return (flat.reshape(rows, n) - (np.arange(rows) * n)[:, None]).astype(np.intp)


class Localizer:
    """One particle filter per robot, all in arrays of shape (robots, particles)."""

    def __init__(self, robots: int, config: FilterConfig | None = None, seed: int = 1,
                 motion: OdometryMotion | None = None, sensor: CentreSensor | None = None):
        if robots < 1:
            raise ValueError("need at least one robot")
        self.config = c = config or FilterConfig()
        self.motion = motion or c.motion
        self.sensor = sensor or CentreSensor(c.meas_std_m)
        self.rules = c.recovery
        self.robots = robots
        self.rng = np.random.default_rng(seed)
        n = self.config.particles
        self.x = np.zeros((robots, n))
        self.y = np.zeros((robots, n))
        self.theta = np.zeros((robots, n))
        self.w = np.full((robots, n), 1.0 / n)
        self.started = np.zeros(robots, dtype=bool)  # has had a pose at all
        self.missed = np.zeros(robots, dtype=int)  # scans since the last measurement
        # released from a blob that stood still while it drove (``held_wrongly``) and not
        # re-seeded since: it takes no blob in the association, only a moving one in the
        # recovery
        self.released_from = np.zeros(robots, dtype=bool)
        # where each robot's filter was last seeded, and whether its blob has since
        # carried it ``rules.confirm_m`` from there (a track that moved is the robot's)
        self.seeded_at = np.zeros((robots, 2))
        self.confirmed = np.zeros(robots, dtype=bool)
        self.drawn = False
        # the last scans' centres and every robot's odometry distance, for still blobs
        self._recent_centres: deque[np.ndarray] = deque(maxlen=self.rules.still_scans)
        self._recent_motion: deque[np.ndarray] = deque(maxlen=self.rules.still_scans)
        self._scan_s = 0.0  # the time between the last two ticks' scans (odometry's period)
        self.resampled = 0  # resampling events so far (all robots)
        self.reseeded = 0  # recoveries so far
        self.released = 0  # robots released from a blob that stood still while they drove

    # prediction ------------------------------------------------------------------
    def draw_over_view(self, geometries: Sequence[ScanGeometry]) -> None:
        """No pose given: particles uniform over the scanners' fields of view, each
        particle in a scanner's drawn at random."""
        c, shape = self.config, self.x.shape
        if len(geometries) == 1:
            pick: np.ndarray | int = 0
        else:
            pick = self.rng.integers(0, len(geometries), shape)

        def of(name: str) -> np.ndarray:
            return np.asarray([getattr(g, name) for g in geometries], dtype=float)[pick]

        span = of("angle_step") * (of("beams") - 1)
        a = of("theta") + of("angle_min") + self.rng.uniform(0.0, 1.0, shape) * span
        r = of("range_max") * np.sqrt(self.rng.uniform(0.0, 1.0, shape))
        self.x = of("x") + r * np.cos(a)
        self.y = of("y") + r * np.sin(a)
        self.theta = self.rng.uniform(-math.pi, math.pi, shape)
        self.w[:] = 1.0 / c.particles
        self.drawn = True

    def predict(self, dist: np.ndarray, dtheta: np.ndarray) -> None:
        """Motion update from each robot's odometry of the last period (distance and
        turn, shape (robots,)): the motion model's sample for every particle."""
        self.x, self.y, self.theta = self.motion.sample(self.x, self.y, self.theta, dist,
                                                        dtheta, self.rng)

    # measurement ---------------------------------------------------------------
    def mean_positions(self) -> np.ndarray:
        return np.stack([(self.w * self.x).sum(axis=1), (self.w * self.y).sum(axis=1)], axis=1)

    def update(self, z: np.ndarray, has: np.ndarray) -> None:
        """Weight robots with a measured centre (z (robots, 2), rows with ``has``) by a
        Gaussian likelihood, then resample where N_eff fell low."""
        rows = np.flatnonzero(has)
        if rows.size == 0:
            return
        c = self.config
        loglik = self.sensor.log_likelihood(self.x[rows], self.y[rows], z[rows])
        logw = np.log(np.maximum(self.w[rows], 1e-300)) + loglik
        logw -= logw.max(axis=1, keepdims=True)
        w = np.exp(logw)
        w /= w.sum(axis=1, keepdims=True)
        self.w[rows] = w
        neff = 1.0 / (w * w).sum(axis=1)
        low = rows[neff < c.resample_below * c.particles]
        if low.size:
            self.resample(low)

    def resample(self, rows: np.ndarray) -> None:
        c, n = self.config, self.config.particles
        idx = systematic_resample(self.w[rows], self.rng.random(rows.size))
        take = np.take_along_axis
        jitter = self.rng.standard_normal((3, rows.size, n))
        self.x[rows] = take(self.x[rows], idx, axis=1) + c.jitter_m * jitter[0]
        self.y[rows] = take(self.y[rows], idx, axis=1) + c.jitter_m * jitter[1]
        self.theta[rows] = take(self.theta[rows], idx, axis=1) + c.jitter_rad * jitter[2]
        self.w[rows] = 1.0 / n
        self.resampled += int(rows.size)

    def reseed(self, robot: int, centre: np.ndarray) -> None:
        """Recovery: particles around a free blob; headings mostly around the filter's
        own (a robot carried off keeps its heading), a fraction uniform."""
        c, n = self.config, self.config.particles
        heading = float(self.estimate_row(robot)[2]) if self.started[robot] else 0.0
        self.x[robot] = centre[0] + c.reseed_std_m * self.rng.standard_normal(n)
        self.y[robot] = centre[1] + c.reseed_std_m * self.rng.standard_normal(n)
        uniform = self.rng.random(n) < (c.reseed_uniform_frac if self.started[robot] else 1.0)
        near = heading + c.reseed_heading_std_rad * self.rng.standard_normal(n)
        self.theta[robot] = np.where(uniform, self.rng.uniform(-math.pi, math.pi, n), near)
        self.w[robot] = 1.0 / n
        self.started[robot] = True
        self.missed[robot] = 0
        self.released_from[robot] = False
        self.seeded_at[robot] = centre
        self.confirmed[robot] = False
        self.reseeded += 1

    def release_held(self, match: np.ndarray, centres: np.ndarray) -> np.ndarray:
        """``match`` without the blobs robots hold wrongly (``held_wrongly``: a blob that
        stood still while the robot drove, on a track that never moved since it was
        seeded), and without any blob for the robots released so: they are lost, and
        found again by the recovery, which gives them no blob that stood still."""
        # only tracks that never moved, and only while a robot never seeded whose wheels
        # stood (one parked, waiting to join) may be the blob's
        waiting = ~self.started & (np.sum(self._recent_motion, axis=0) == 0)
        if not waiting.any():
            return np.where(self.released_from, -1, match)
        k = self.rules.held_scans
        recent = list(self._recent_centres)[-k:]
        # the odometry between the window's first scan and this one (a tick's odometry
        # is the motion up to its scan: the window's first is from before it)
        between = list(self._recent_motion)[-k + 1:] if k > 1 else []
        drove = np.sum(between, axis=0) if between else np.zeros(self.robots)
        held = np.where(self.confirmed, -1, match)
        wrong = held_wrongly(held, centres, recent, drove, self.rules)
        self.released += int(wrong.sum())
        self.released_from |= wrong
        # lost at once; lost longer only by the scans it drives (``advance_missed``)
        self.missed[wrong] = np.maximum(self.missed[wrong], self.rules.lost_after)
        return np.where(self.released_from, -1, match)

    def advance_missed(self, has: np.ndarray, dist: np.ndarray) -> None:
        """Scans since each robot's last measurement; a released robot's count only
        those it drove in: standing where it was lost, hidden behind a parked robot, it
        stays within the reach of a lost robot's first scans, and does not take a
        stranger's blob across the scene when it drives out."""
        still = self.released_from & (np.abs(np.asarray(dist, dtype=float)) == 0.0)
        self.missed = np.where(has, 0, self.missed + np.where(still, 0, 1))

    def confirm(self, has: np.ndarray) -> None:
        """Tracks measured this far from where they were seeded are the robots' own."""
        rows = np.flatnonzero(has & ~self.confirmed)  # once confirmed, for good
        if rows.size:
            at = self.mean_positions()[rows]
            moved = np.hypot(*(at - self.seeded_at[rows]).T) > self.rules.confirm_m
            self.confirmed[rows[moved]] = True

    def recover(self, centres: np.ndarray, used: np.ndarray) -> None:
        """Re-seed lost robots on robot-shaped blobs no robot took (``recovery``)."""
        lost = ~self.started | (self.missed >= self.rules.lost_after)
        if not lost.any() or used.all():  # most ticks: nothing to choose, so nothing to
            return  # measure (still blobs, motion, predictions) for the choice
        known = len(self._recent_centres) == self.rules.still_scans  # enough to tell
        still = still_blobs(centres, self._recent_centres, self.rules.still_m) \
            if known else None
        k = self.rules.held_scans
        if still is None and self.released_from.any() and len(self._recent_centres) >= k:
            # a robot released for driving while its blob stood takes no blob that
            # stood as long, nor does it hold one from the others meanwhile
            still = still_blobs(centres, list(self._recent_centres)[-k:],
                                self.rules.held_still_m)
        moved = (np.sum(self._recent_motion, axis=0) > self.rules.moved_m
                 if self._recent_motion else np.zeros(self.robots, dtype=bool))
        moved = moved | self.released_from  # it drove while its blob stood
        r = self.rules
        fast = (fast_blobs(centres, self._recent_centres, r.follow_m, r.top_speed_m_s,
                           self._scan_s) if r.top_speed_m_s > 0 and self._scan_s > 0
                else None)
        for robot, j in recovery(centres, used, self.mean_positions(), self.started,
                                 self.missed, still, moved, self.rules, fast,
                                 self._scan_s):
            self.reseed(robot, centres[j])

    # output ----------------------------------------------------------------------
    def estimate_row(self, robot: int) -> tuple[float, float, float, float, float, float]:
        w = self.w[robot]
        mx = float(w @ self.x[robot])
        my = float(w @ self.y[robot])
        s, co = float(w @ np.sin(self.theta[robot])), float(w @ np.cos(self.theta[robot]))
        mth = math.atan2(s, co)
        vx = float(w @ (self.x[robot] - mx) ** 2)
        vy = float(w @ (self.y[robot] - my) ** 2)
        vth = float(w @ wrap_pi_array(self.theta[robot] - mth) ** 2)
        return mx, my, mth, vx, vy, vth

    def step(self, ranges: np.ndarray, geometry: ScanGeometry, dist: np.ndarray,
             dtheta: np.ndarray) -> list[Estimate]:
        """One scan: predict every robot with its odometry since the last scan, measure
        the centres, assign them, update, recover lost robots; one estimate per robot."""
        return self.step_scans([(ranges, geometry)], dist, dtheta)

    def step_scans(self, scans: Sequence[tuple[np.ndarray, ScanGeometry]],
                   dist: np.ndarray, dtheta: np.ndarray, dt: float = 0.0) -> list[Estimate]:
        """``step`` for one tick seen by a row of scanners: the centres of every scan,
        one per robot where two scanners see the same robot (``merge_centres``). ``dt``
        is the odometry's period (with ``config.blobs``, for each robot's speed)."""
        if not scans:
            raise ValueError("a tick needs at least one scan")
        if not self.drawn:
            self.draw_over_view([g for _, g in scans])
        self.predict(dist, dtheta)
        if self.config.blobs:
            return self._step_blobs(scans, np.asarray(dist, dtype=float), dt)
        centres = merge_centres([measure_centres(r, g, self.config) for r, g in scans],
                                self.config.radius_m)
        match = assign(self.mean_positions(), centres, self.started, self.config.gate_m)
        self._recent_centres.append(centres)
        self._recent_motion.append(np.abs(np.asarray(dist, dtype=float)))
        match = self.release_held(match, centres)
        has = match >= 0
        z = np.zeros((self.robots, 2))
        z[has] = centres[match[has]]
        self.update(z, has)
        self.confirm(has)
        self.advance_missed(has, dist)
        used = np.zeros(centres.shape[0], dtype=bool)
        used[match[has]] = True
        self.recover(centres, used)
        return self.estimates(has)

    def _step_blobs(self, scans: Sequence[tuple[np.ndarray, ScanGeometry]],
                    dist: np.ndarray, dt: float) -> list[Estimate]:
        """The measure-assign-update-recover of ``step_scans`` on ``measure_blobs``: a
        partial blob is a robot's only within ``partial_gate_m`` of its prediction and
        never re-seeds one; an assigned centre is moved from its returns' mean time to
        the scan's along the robot's heading at its odometry's speed."""
        c = self.config
        self._scan_s = dt
        blobs = merge_blobs([measure_blobs(r, g, c) for r, g in scans], c.radius_m)
        centres = blobs.centres
        gates = np.where(blobs.full, c.gate_m, min(c.partial_gate_m, c.gate_m))
        predicted = self.mean_positions()
        match = assign(predicted, centres, self.started, gates)
        self._recent_centres.append(centres)
        self._recent_motion.append(np.abs(dist))
        match = self.release_held(match, centres)
        has = match >= 0
        z = np.zeros((self.robots, 2))
        z[has] = centres[match[has]]
        if dt > 0 and has.any():
            heading = np.arctan2((self.w * np.sin(self.theta)).sum(axis=1),
                                 (self.w * np.cos(self.theta)).sum(axis=1))
            ahead = -blobs.tau[match[has]] * dist[has] / dt  # metres since the returns
            z[has, 0] += ahead * np.cos(heading[has])
            z[has, 1] += ahead * np.sin(heading[has])
        if c.body_radius_m > 0 and has.any():
            self._outline(z, has, scans)
        self.update(z, has)
        self.confirm(has)
        self.advance_missed(has, dist)
        used = ~blobs.full.copy()  # a partial blob starts no track
        used[match[has]] = True
        self.recover(centres, used)
        return self.estimates(has)

    def _outline(self, z: np.ndarray, has: np.ndarray,
                 scans: Sequence[tuple[np.ndarray, ScanGeometry]]) -> None:
        """Centres fitted with a circle of ``radius_m`` to a Create's outline, moved to
        the outline's: the side a scanner sees is the bumper's (in front), the body's
        (behind) or some of each, and a smaller radius seen puts the fitted circle's
        centre that much farther than the robot's along the line of sight."""
        c = self.config
        heading = np.arctan2((self.w * np.sin(self.theta)).sum(axis=1),
                             (self.w * np.cos(self.theta)).sum(axis=1))
        rows = np.flatnonzero(has)
        for i in rows.tolist():
            near = min(scans, key=lambda s: float(np.hypot(z[i, 0] - s[1].x, z[i, 1] - s[1].y)))
            g = near[1]
            lx, ly = z[i, 0] - g.x, z[i, 1] - g.y
            d = math.hypot(lx, ly)
            if d <= 0:
                continue
            to_scanner = math.atan2(-ly, -lx)
            off = abs(math.remainder(float(heading[i]) - to_scanner, 2.0 * math.pi))
            front = 1.0 - off / math.pi  # share of the arc seen that is the bumper
            seen = c.body_radius_m + (c.bumper_radius_m - c.body_radius_m) * front
            shift = c.radius_m - seen
            z[i, 0] -= shift * lx / d
            z[i, 1] -= shift * ly / d

    def cloud(self, size: int) -> list[tuple[list[float], list[float]]]:
        """Every robot's particles, ``size`` of them taken evenly (for viewers): (x, y)
        lists per robot. Draws no random numbers, so showing a cloud changes no run."""
        n = self.config.particles
        pick = np.linspace(0, n - 1, min(size, n)).astype(int)
        return [(self.x[r, pick].tolist(), self.y[r, pick].tolist())
                for r in range(self.robots)]

    def estimates(self, measured: np.ndarray) -> list[Estimate]:
        """Every robot's weighted mean pose (circular mean heading) and variances."""
        w = self.w
        mx = (w * self.x).sum(axis=1)
        my = (w * self.y).sum(axis=1)
        s, c = (w * np.sin(self.theta)).sum(axis=1), (w * np.cos(self.theta)).sum(axis=1)
        mth = np.arctan2(s, c)
        vx = (w * (self.x - mx[:, None]) ** 2).sum(axis=1)
        vy = (w * (self.y - my[:, None]) ** 2).sum(axis=1)
        # heading variance of a wrapped normal from the mean resultant length R
        vth = -2.0 * np.log(np.clip(np.hypot(s, c), 1e-12, 1.0))
        lost = ~self.started | (self.missed >= self.rules.lost_after)
        rows = zip(mx.tolist(), my.tolist(), mth.tolist(), vx.tolist(), vy.tolist(),
                   vth.tolist(), measured.tolist(), lost.tolist(), strict=True)
        return [Estimate(*row) for row in rows]
