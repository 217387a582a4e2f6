"""The localizer's pure core: laser scan -> robot centres -> one particle filter per robot.

Thesis chapter 5 (the particle filter) and section 6.1.5 (laser localisation): one
laser range finder behind the team sees the robots as arcs of circles; each robot's
odometry drives its particle filter's prediction, and the centre measured from the
scan weights the particles.

The steps of ``Localizer.step`` (one scan):

1. ``split_blobs``: consecutive returns closer than ``jump_m`` to each other form a
   blob; misses (maximum range) and range jumps split blobs.
2. ``blob_centre``: the nearest return of the blob plus the robot radius along its
   bearing (thesis 6.1.5), refined by a least-squares fit of a circle of known
   radius to all the blob's returns (the thesis's estimate is the start; the fit
   removes the 0.25 degree bearing quantisation). Blobs wider than a robot or that
   do not fit a circle (walls) are not robots.
3. ``assign``: measured centres are matched to the robots' predicted positions by
   minimum total squared distance, each pair gated at ``gate_m``; a blob that fits
   no robot is ignored.
4. The particle filter (algorithm 5.1), vectorised over robots and particles:
   odometry prediction with Gaussian noise (eq. 5.2; here the noise grows with the
   distance and turn of the period), a Gaussian likelihood of the measured centre
   (eq. 5.3), and systematic resampling (the thesis's correction step) when the
   effective sample size 1 / sum(w^2) falls below ``resample_below`` * N. A robot
   without a measurement (occluded) keeps its prediction.
5. Recovery: the filters start with no pose (particles drawn over the scanners'
   fields of view); on the first scan the robots take the blobs in the order of the
   edge (robot 0 leftmost), which is the order of the team's initial segments. A
   robot whose filter has had no measurement for ``lost_after`` scans is re-seeded
   on a blob no robot took (a kidnapped robot, or one that was hidden): the nearest
   claimant first, each within a reach that grows with the scans it has been lost,
   and never on a blob whose motion its odometry contradicts (a blob standing
   still is no robot that drove: a robot parked in view, waiting to join, is not
   taken for a driving one that was hidden behind it at the start).

Heading is never measured: it comes from odometry and from which headings carry
the particles to where the scans see the robot.

No I/O, no threads, no clock: time and odometry come in as arguments; the random
numbers come from a seeded numpy Generator owned by the ``Localizer``.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from agent.phase import wrap_pi_array


@dataclass(frozen=True)
class FilterConfig:
    """Localizer parameters; SI units, angles in radians."""

    particles: int = 1000
    radius_m: float = 0.17  # robot radius (iRobot Create)
    meas_std_m: float = 0.02  # std of a measured centre, per axis (likelihood)
    odom_dist_frac: float = 0.05  # std of driven distance per metre driven
    odom_dist_floor_m: float = 0.002  # std of driven distance per period
    odom_turn_frac: float = 0.05  # std of turn per radian turned
    odom_turn_per_m: float = 0.05  # std of turn per metre driven, rad/m
    odom_turn_floor_rad: float = 0.004  # std of turn per period
    resample_below: float = 0.5  # resample when N_eff < this fraction of N
    jitter_m: float = 0.001  # roughening after resampling, per axis
    jitter_rad: float = 0.005
    jump_m: float = 0.10  # a gap between returns larger than this splits blobs
    min_returns: int = 3  # fewer returns than this: not a robot (nor a useful arc)
    width_margin_m: float = 0.06  # a blob wider than 2 r + this is not a robot
    fit_rms_m: float = 0.03  # a blob whose circle fit is worse than this is not a robot
    gate_m: float = 0.25  # a centre farther than this from a prediction is not that robot
    lost_after: int = 3  # scans without a measurement before a free blob may re-seed
    # A lost robot may re-seed on a free blob this far from its prediction, and this much
    # farther per scan it has been lost: an occluded robot does not jump to a stranger
    # across the scene, a kidnapped one is found within a few scans of its new place.
    reseed_reach_m: float = 0.25
    reseed_growth_m: float = 0.1
    # A free blob that stood still (within still_m) over the last still_scans scans is
    # not a robot whose odometry says it drove more than moved_m meanwhile (a robot
    # parked in view, waiting to join, is no lost robot that is driving).
    still_scans: int = 10
    still_m: float = 0.02
    moved_m: float = 0.05
    reseed_std_m: float = 0.02
    reseed_heading_std_rad: float = 0.2  # around the filter's own heading
    reseed_uniform_frac: float = 0.2  # of re-seeded particles with any heading
    refine: bool = True  # fit a circle to the blob after the thesis's estimate

    def __post_init__(self) -> None:
        if self.particles < 2:
            raise ValueError("need at least two particles")
        if self.radius_m <= 0 or self.meas_std_m <= 0 or self.gate_m <= 0:
            raise ValueError("radius, measurement std and gate must be positive")
        if not 0.0 < self.resample_below <= 1.0:
            raise ValueError("resample_below must be in (0, 1]")


@dataclass(frozen=True)
class ScanGeometry:
    """Where the scanner is and how its beams are laid out (from the Scan message)."""

    x: float
    y: float
    theta: float
    angle_min: float
    angle_step: float
    range_max: float
    beams: int = 361

    @classmethod
    def of(cls, scan: Any) -> ScanGeometry:
        """The geometry a ``wire.Scan`` carries."""
        return cls(scan.scanner_x, scan.scanner_y, scan.scanner_theta, scan.angle_min,
                   scan.angle_step, scan.range_max, len(scan.ranges))


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
    lost: bool  # no pose yet, or no measurement for ``lost_after`` scans


# --- scan -> blobs -> centres ------------------------------------------------------


def split_blobs(ranges: np.ndarray, geometry: ScanGeometry, jump_m: float) -> list[np.ndarray]:
    """Beam indices of each blob: runs of returns (below the maximum range) whose
    neighbouring returns are less than ``jump_m`` apart."""
    starts, ends = blob_spans(ranges, geometry, jump_m)
    return [np.arange(a, b) for a, b in zip(starts.tolist(), ends.tolist(), strict=True)]


def blob_spans(ranges: np.ndarray, geometry: ScanGeometry, jump_m: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """``split_blobs`` as each blob's first beam and the beam after its last."""
    r = np.asarray(ranges, dtype=float)
    hit = r < geometry.range_max - 1e-6
    if not hit.any():
        return np.empty(0, dtype=np.intp), np.empty(0, dtype=np.intp)
    a = geometry.theta + geometry.angle_min + geometry.angle_step * np.arange(r.size)
    px, py = r * np.cos(a), r * np.sin(a)
    gap = np.hypot(np.diff(px), np.diff(py))
    # a blob breaks after beam i if beam i or i+1 is a miss, or the two are far apart
    breaks = ~hit[:-1] | ~hit[1:] | (gap > jump_m)
    starts = np.flatnonzero(np.concatenate([[True], breaks]))
    ends = np.append(starts[1:], r.size)
    keep = hit[starts]
    return starts[keep], ends[keep]


def blob_points(ranges: np.ndarray, geometry: ScanGeometry, beams: np.ndarray) -> np.ndarray:
    """World coordinates (k, 2) of the blob's returns."""
    r = np.asarray(ranges, dtype=float)[beams]
    a = geometry.theta + geometry.angle_min + geometry.angle_step * beams
    return np.stack([geometry.x + r * np.cos(a), geometry.y + r * np.sin(a)], axis=1)


def nearest_return_centre(
    ranges: np.ndarray, geometry: ScanGeometry, beams: np.ndarray, radius: float
) -> np.ndarray:
    """Thesis 6.1.5: the blob's nearest return, pushed back by the robot radius along
    its bearing."""
    r = np.asarray(ranges, dtype=float)
    j = int(beams[np.argmin(r[beams])])
    a = geometry.theta + geometry.angle_min + geometry.angle_step * j
    d = r[j] + radius
    return np.array([geometry.x + d * math.cos(a), geometry.y + d * math.sin(a)])


def fit_circle(points: np.ndarray, radius: float, start: np.ndarray,
               iterations: int = 6) -> tuple[np.ndarray, float]:
    """Least-squares centre of a circle of known ``radius`` through ``points``
    (Gauss-Newton from ``start``); returns the centre and the RMS residual."""
    cx, cy = float(start[0]), float(start[1])
    px, py = points[:, 0], points[:, 1]
    for _ in range(iterations):
        dx, dy = px - cx, py - cy
        dist = np.maximum(np.hypot(dx, dy), 1e-9)
        res = dist - radius
        jx, jy = -dx / dist, -dy / dist  # d(dist)/d(centre)
        a, b, d = float(jx @ jx), float(jx @ jy), float(jy @ jy)
        gx, gy = -float(jx @ res), -float(jy @ res)
        det = a * d - b * b
        if abs(det) < 1e-12:
            break
        sx, sy = (d * gx - b * gy) / det, (a * gy - b * gx) / det  # the 2x2 normal equations
        cx, cy = cx + sx, cy + sy
        if sx * sx + sy * sy < 1e-12:
            break
    res = np.hypot(px - cx, py - cy) - radius
    return np.array([cx, cy]), float(np.sqrt(np.mean(res * res)))


def blob_centre(ranges: np.ndarray, geometry: ScanGeometry, beams: np.ndarray,
                config: FilterConfig) -> np.ndarray | None:
    """The centre of the robot seen as this blob, or None if the blob is no robot."""
    if beams.size < config.min_returns:
        return None
    pts = blob_points(ranges, geometry, beams)
    width = float(np.hypot(*(pts[-1] - pts[0])))
    if width > 2.0 * config.radius_m + config.width_margin_m:
        return None
    centre = nearest_return_centre(ranges, geometry, beams, config.radius_m)
    if not config.refine or beams.size < 3:
        return centre
    # Start the fit on the blob's middle bearing: with range noise the nearest
    # return may be any beam of the robot's front, up to several cm to the side.
    mid = geometry.theta + geometry.angle_min + geometry.angle_step * 0.5 * (beams[0] + beams[-1])
    reach = float(np.hypot(*(centre - (geometry.x, geometry.y))))
    start = np.array([geometry.x + reach * math.cos(mid), geometry.y + reach * math.sin(mid)])
    fitted, rms = fit_circle(pts, config.radius_m, start)
    if rms > config.fit_rms_m:
        return None
    if np.hypot(*(fitted - start)) > config.radius_m:  # a fit gone astray: keep the thesis's
        return centre
    return fitted


def measure_centres(ranges: np.ndarray, geometry: ScanGeometry,
                    config: FilterConfig, iterations: int = 6) -> np.ndarray:
    """Centres (m, 2) of every robot-shaped blob of a scan: ``blob_centre`` for all
    blobs at once (blobs padded to one length and masked, one Gauss-Newton for all),
    so thirty robots cost little more than three."""
    starts, ends = blob_spans(ranges, geometry, config.jump_m)
    big_enough = ends - starts >= config.min_returns
    if not big_enough.any():
        return np.empty((0, 2))
    r_all = np.asarray(ranges, dtype=float)
    first = starts[big_enough]
    lengths = ends[big_enough] - first
    width = int(lengths.max())
    offs = np.minimum(np.arange(width)[None, :], lengths[:, None] - 1)
    beams = first[:, None] + offs  # (B, K), padded with each blob's last beam
    mask = (np.arange(width)[None, :] < lengths[:, None]).astype(float)
    base = geometry.theta + geometry.angle_min
    ang = base + geometry.angle_step * beams
    rng = r_all[beams]
    px = geometry.x + rng * np.cos(ang)
    py = geometry.y + rng * np.sin(ang)
    last = lengths - 1
    rows = np.arange(first.size)
    chord = np.hypot(px[rows, last] - px[:, 0], py[rows, last] - py[:, 0])
    # the thesis's estimate: nearest return plus the radius along its bearing
    near = np.argmin(np.where(mask > 0, rng, np.inf), axis=1)
    reach = rng[rows, near] + config.radius_m
    thesis = np.stack([geometry.x + reach * np.cos(ang[rows, near]),
                       geometry.y + reach * np.sin(ang[rows, near])], axis=1)
    ok = chord <= 2.0 * config.radius_m + config.width_margin_m
    if not config.refine:
        return thesis[ok]
    mid = base + geometry.angle_step * 0.5 * (beams[:, 0] + beams[rows, last])
    cx = geometry.x + reach * np.cos(mid)
    cy = geometry.y + reach * np.sin(mid)
    sx0, sy0 = cx.copy(), cy.copy()
    for _ in range(iterations):
        dx, dy = px - cx[:, None], py - cy[:, None]
        dist = np.maximum(np.hypot(dx, dy), 1e-9)
        res = (dist - config.radius_m) * mask
        jx, jy = -dx / dist * mask, -dy / dist * mask
        a, b, d = (jx * jx).sum(1), (jx * jy).sum(1), (jy * jy).sum(1)
        gx, gy = -(jx * res).sum(1), -(jy * res).sum(1)
        det = a * d - b * b
        good = np.abs(det) > 1e-12
        det = np.where(good, det, 1.0)
        cx = cx + np.where(good, (d * gx - b * gy) / det, 0.0)
        cy = cy + np.where(good, (a * gy - b * gx) / det, 0.0)
    res = (np.hypot(px - cx[:, None], py - cy[:, None]) - config.radius_m) * mask
    rms = np.sqrt((res * res).sum(1) / lengths)
    ok &= rms <= config.fit_rms_m
    astray = np.hypot(cx - sx0, cy - sy0) > config.radius_m  # keep the thesis's estimate
    fitted = np.stack([np.where(astray, thesis[:, 0], cx), np.where(astray, thesis[:, 1], cy)],
                      axis=1)
    return fitted[ok]


def merge_centres(per_scan: Sequence[np.ndarray], radius: float) -> np.ndarray:
    """The centres (m, 2) several scanners measured in one tick, one per robot: a
    centre less than a robot's radius from one the earlier scanners measured is the
    same robot (two robots' centres are two radii apart at least), and the two are
    averaged. One scan's centres are returned as they are."""
    if len(per_scan) == 1:
        return per_scan[0]
    merged = np.empty((0, 2))
    counts = np.empty(0)
    for centres in per_scan:
        centres = np.asarray(centres, dtype=float).reshape(-1, 2)
        if merged.shape[0] and centres.shape[0]:
            d = np.hypot(centres[:, None, 0] - merged[None, :, 0],
                         centres[:, None, 1] - merged[None, :, 1])  # (this scan's, earlier)
            j = d.argmin(axis=1)
            same = d[np.arange(centres.shape[0]), j] < radius
            sums = merged * counts[:, None]
            np.add.at(sums, j[same], centres[same])
            np.add.at(counts, j[same], 1.0)
            merged = sums / counts[:, None]
            centres = centres[~same]
        merged = np.vstack([merged, centres])
        counts = np.concatenate([counts, np.ones(centres.shape[0])])
    return merged


def assign(predicted: np.ndarray, candidates: np.ndarray, active: np.ndarray,
           gate_m: float) -> np.ndarray:
    """For each robot, the index of its measured centre, or -1: minimum total squared
    distance over robots in ``active``, each pair gated at ``gate_m``."""
    out = np.full(predicted.shape[0], -1, dtype=int)
    rows = np.flatnonzero(active)
    if rows.size == 0 or candidates.shape[0] == 0:
        return out
    d2 = ((predicted[rows, None, :] - candidates[None, :, :]) ** 2).sum(axis=2)
    big = 1e6
    cost = np.where(d2 <= gate_m * gate_m, d2, big)
    r_idx, c_idx = linear_sum_assignment(cost)
    ok = cost[r_idx, c_idx] < big
    out[rows[r_idx[ok]]] = c_idx[ok]
    return out


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

    def __init__(self, robots: int, config: FilterConfig | None = None, seed: int = 1):
        if robots < 1:
            raise ValueError("need at least one robot")
        self.config = config or FilterConfig()
        self.robots = robots
        self.rng = np.random.default_rng(seed)
        n = self.config.particles
        self.x = np.zeros((robots, n))
        self.y = np.zeros((robots, n))
        self.theta = np.zeros((robots, n))
        self.w = np.full((robots, n), 1.0 / n)
        self.started = np.zeros(robots, dtype=bool)  # has had a pose at all
        self.missed = np.zeros(robots, dtype=int)  # scans since the last measurement
        self.drawn = False
        # the last scans' centres and every robot's odometry distance, for still blobs
        self._recent_centres: deque[np.ndarray] = deque(maxlen=self.config.still_scans)
        self._recent_motion: deque[np.ndarray] = deque(maxlen=self.config.still_scans)
        self.resampled = 0  # resampling events so far (all robots)
        self.reseeded = 0  # recoveries so far

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
        turn, shape (robots,)), with noise sampled per particle; the arc is
        integrated at its mid heading."""
        c, shape = self.config, self.x.shape
        dist = np.asarray(dist, dtype=float)[:, None]
        dtheta = np.asarray(dtheta, dtype=float)[:, None]
        sd = c.odom_dist_frac * np.abs(dist) + c.odom_dist_floor_m
        st = (c.odom_turn_frac * np.abs(dtheta) + c.odom_turn_per_m * np.abs(dist)
              + c.odom_turn_floor_rad)
        noise = self.rng.standard_normal((2, *shape))
        d = dist + sd * noise[0]
        dt = dtheta + st * noise[1]
        mid = self.theta + 0.5 * dt
        self.x += d * np.cos(mid)
        self.y += d * np.sin(mid)
        self.theta += dt  # left unwrapped: only its sine and cosine are ever used

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
        dx = self.x[rows] - z[rows, 0:1]
        dy = self.y[rows] - z[rows, 1:2]
        loglik = -(dx * dx + dy * dy) / (2.0 * c.meas_std_m**2)
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
        self.reseeded += 1

    def recover(self, centres: np.ndarray, used: np.ndarray) -> None:
        """Re-seed lost robots from robot-shaped blobs no robot took. With nobody
        started, robots take the blobs in the order of the edge. Otherwise the lost
        robots that had a pose take the free blobs nearest their predictions first
        (pairs by distance over all of them, not robot by robot), each within its
        reach (``reseed_reach_m`` plus ``reseed_growth_m`` per scan lost), and never a
        blob that stood still while its odometry drove (nor, for one never seeded, a
        blob that moved while it stood: ``still_blobs``, ``moved``); a robot
        unmeasured for fewer scans than ``lost_after`` takes part too, holding the
        blob it is nearest without re-seeding on it; robots never seeded take what is
        left in the order of the edge."""
        c = self.config
        lost = np.flatnonzero(~self.started | (self.missed >= c.lost_after))
        free = [j for j in range(centres.shape[0]) if not used[j]]
        if lost.size == 0 or not free:
            return
        if not self.started.any():
            # nobody has a pose yet: robots take the blobs in the order of the edge
            order = sorted(free, key=lambda j: float(centres[j, 0]))
            for robot, j in zip(lost.tolist(), order, strict=False):
                self.reseed(robot, centres[j])
            return
        still = self.still_blobs(centres)
        moved = self.moved()
        known = len(self._recent_centres) == c.still_scans  # enough scans to tell

        def fits(robot: int, j: int) -> bool:
            """A blob that stood still is not a robot that drove; nor is one that moved
            a robot never seeded whose odometry stood (one parked, waiting to join).
            A robot with a pose may take a moving blob though its odometry stood: its
            wheels may be what failed."""
            if not known:
                return True
            if still[j]:
                return not moved[robot]
            return bool(self.started[robot] or moved[robot])

        predicted = self.mean_positions()
        pairs = []
        # every robot that went unmeasured claims; one not lost yet only holds its blob
        for robot in np.flatnonzero(self.started & (self.missed > 0)).tolist():
            reach = c.reseed_reach_m + c.reseed_growth_m * float(self.missed[robot])
            for j in free:
                d = float(np.hypot(*(centres[j] - predicted[robot])))
                if d <= reach and fits(robot, j):
                    pairs.append((d, robot, j))
        taken: set[int] = set()
        for _, robot, j in sorted(pairs):
            if robot in taken or j not in free:
                continue
            free.remove(j)
            taken.add(robot)
            if self.missed[robot] >= c.lost_after:
                self.reseed(robot, centres[j])
        for robot in lost[~self.started[lost]].tolist():
            fitting = [j for j in free if fits(robot, j)]
            if not fitting:
                continue
            j = min(fitting, key=lambda j: float(centres[j, 0]))
            free.remove(j)
            self.reseed(robot, centres[j])

    def still_blobs(self, centres: np.ndarray) -> np.ndarray:
        """For each centre of this scan, whether a centre lay within ``still_m`` of it in
        every one of the last ``still_scans`` scans (this one included)."""
        c = self.config
        out = np.full(centres.shape[0], True)
        for earlier in self._recent_centres:
            if not out.any():
                break
            if earlier.shape[0] == 0:
                return np.zeros(centres.shape[0], dtype=bool)
            d = np.hypot(centres[:, None, 0] - earlier[None, :, 0],
                         centres[:, None, 1] - earlier[None, :, 1])
            out &= d.min(axis=1) <= c.still_m
        return out

    def moved(self) -> np.ndarray:
        """Whether each robot's odometry drove more than ``moved_m`` over the last
        ``still_scans`` scans."""
        if not self._recent_motion:
            return np.zeros(self.robots, dtype=bool)
        return np.sum(self._recent_motion, axis=0) > self.config.moved_m

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
                   dist: np.ndarray, dtheta: np.ndarray) -> list[Estimate]:
        """``step`` for one tick seen by a row of scanners: the centres of every scan,
        one per robot where two scanners see the same robot (``merge_centres``)."""
        if not scans:
            raise ValueError("a tick needs at least one scan")
        if not self.drawn:
            self.draw_over_view([g for _, g in scans])
        self.predict(dist, dtheta)
        centres = merge_centres([measure_centres(r, g, self.config) for r, g in scans],
                                self.config.radius_m)
        match = assign(self.mean_positions(), centres, self.started, self.config.gate_m)
        has = match >= 0
        z = np.zeros((self.robots, 2))
        z[has] = centres[match[has]]
        self.update(z, has)
        self.missed = np.where(has, 0, self.missed + 1)
        used = np.zeros(centres.shape[0], dtype=bool)
        used[match[has]] = True
        self._recent_centres.append(centres)
        self._recent_motion.append(np.abs(np.asarray(dist, dtype=float)))
        self.recover(centres, used)
        return self.estimates(has)

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
        lost = ~self.started | (self.missed >= self.config.lost_after)
        rows = zip(mx.tolist(), my.tolist(), mth.tolist(), vx.tolist(), vy.tolist(),
                   vth.tolist(), measured.tolist(), lost.tolist(), strict=True)
        return [Estimate(*row) for row in rows]
