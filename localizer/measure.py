"""The localizer's measurement: one scan -> the robots' centres (thesis 6.1.5), the
front end nav2's AMCL would call its laser model's data. Pure functions of the ranges
and the scanner's geometry.

``split_blobs``/``blob_spans``: consecutive returns closer than ``jump_m`` to each other
form a blob; misses (maximum range) and range jumps split blobs. ``measure_centres``:
each blob's nearest return plus the robot radius along its bearing (the thesis's
estimate), refined by a least-squares fit of a circle of known radius to all the
blob's returns; blobs wider than a robot or not circular (walls) are no robots.
``merge_centres``: one centre per robot when a row of scanners sees it twice.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from localizer.core import FilterConfig


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


# --- the lab's scans: spikes, mixed pixels, partial robots and the sweep's timing ----------


def median3(ranges: np.ndarray) -> np.ndarray:
    """Each range replaced by the median of itself and its two neighbours (the ends kept):
    an isolated spurious return or dropout inside a robot's arc is gone, a step (a
    silhouette edge) stays where it is."""
    r = np.asarray(ranges, dtype=float)
    if r.size < 3:
        return r.copy()
    out = r.copy()
    out[1:-1] = np.median(np.stack([r[:-2], r[1:-1], r[2:]]), axis=0)
    return out


def sweep_offsets(beams: int, rotation_s: float, interlace: int) -> np.ndarray:
    """When each beam of an LMS 2xx scan is measured, relative to the scan's time (its
    last beam), s: the mirror turns once per ``rotation_s`` and sweeps the 180 degrees in
    half a turn; at 0.5 degree two turns interlace (even beams in the first, odd in the
    second). From the device's timing, as the driver knows it."""
    j = np.arange(beams)
    span = (interlace - 1) * rotation_s + 0.5 * rotation_s
    return -span + (j % interlace) * rotation_s + j / max(beams - 1, 1) * 0.5 * rotation_s


@dataclass(frozen=True)
class Blobs:
    """The robot-shaped blobs of one tick: centre, whether the robot was seen whole (a
    blob as wide as a robot: only such blobs may start or re-seed a track), and the mean
    time of the returns fitted, relative to the scan's (s, <= 0)."""

    centres: np.ndarray  # (m, 2)
    full: np.ndarray  # (m,) bool
    tau: np.ndarray  # (m,)


def measure_blobs(ranges: np.ndarray, geometry: ScanGeometry, config: FilterConfig) -> Blobs:
    """``measure_centres`` for a real LMS: the scan median-filtered first
    (``config.median3``), ``config.trim_edges`` returns dropped at each end of a blob
    before the circle fit (the mixed pixels of a silhouette edge), the fit's worst
    return dropped and the fit repeated when it lies over three times the RMS out, and
    each blob flagged full (its chord at least ``config.full_chord_m``) and timed."""
    r = median3(ranges) if config.median3 else np.asarray(ranges, dtype=float)
    starts, ends = blob_spans(r, geometry, config.jump_m)
    times = sweep_offsets(r.size, config.rotation_s, config.interlace)
    centres, full, tau = [], [], []
    trim = config.trim_edges
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        beams = np.arange(a, b)
        pts_all = blob_points(r, geometry, beams)
        chord = float(np.hypot(*(pts_all[-1] - pts_all[0])))
        if chord > 2.0 * config.radius_m + config.width_margin_m:
            continue
        if beams.size - 2 * trim >= config.min_returns:
            beams = beams[trim:beams.size - trim]
        if beams.size < config.min_returns:
            continue
        centre = _robust_fit(r, geometry, beams, config)
        if centre is None:
            continue
        fitted, used = centre
        centres.append(fitted)
        full.append(chord >= config.full_chord_m)
        tau.append(float(times[used].mean()))
    if not centres:
        return Blobs(np.empty((0, 2)), np.empty(0, dtype=bool), np.empty(0))
    return Blobs(np.array(centres), np.array(full, dtype=bool), np.array(tau))


def _robust_fit(r: np.ndarray, geometry: ScanGeometry, beams: np.ndarray,
                config: FilterConfig) -> tuple[np.ndarray, np.ndarray] | None:
    """The circle fit of ``blob_centre`` on ``beams``, once more without the worst return
    if it is an outlier; None if the blob is no robot."""
    pts = blob_points(r, geometry, beams)
    near = int(beams[np.argmin(r[beams])])
    reach = float(r[near]) + config.radius_m
    mid = geometry.theta + geometry.angle_min + geometry.angle_step * 0.5 * (beams[0] + beams[-1])
    start = np.array([geometry.x + reach * math.cos(mid), geometry.y + reach * math.sin(mid)])
    fitted, rms = fit_circle(pts, config.radius_m, start)
    res = np.abs(np.hypot(*(pts - fitted).T) - config.radius_m)
    worst = int(np.argmax(res))
    if beams.size > config.min_returns and res[worst] > 3.0 * max(rms, 1e-4) and rms > 0.003:
        keep = np.ones(beams.size, dtype=bool)
        keep[worst] = False
        beams, pts = beams[keep], pts[keep]
        fitted, rms = fit_circle(pts, config.radius_m, start)
    if rms > config.fit_rms_m or np.hypot(*(fitted - start)) > config.radius_m:
        return None
    return fitted, beams


def merge_blobs(per_scan: Sequence[Blobs], radius: float) -> Blobs:
    """``merge_centres`` for ``Blobs``: one blob per robot across a row of scanners, full
    if any scanner saw it whole, timed as the mean of its scanners'."""
    if len(per_scan) == 1:
        return per_scan[0]
    centres = merge_centres([b.centres for b in per_scan], radius)
    every = [b for b in per_scan if b.centres.shape[0]]
    if not every or centres.shape[0] == 0:
        return Blobs(centres, np.zeros(centres.shape[0], dtype=bool), np.zeros(centres.shape[0]))
    c = np.vstack([b.centres for b in every])
    f = np.concatenate([b.full for b in every])
    t = np.concatenate([b.tau for b in every])
    d = np.hypot(centres[:, None, 0] - c[None, :, 0], centres[:, None, 1] - c[None, :, 1])
    near = d < radius
    full = (near & f[None, :]).any(axis=1)
    tau = (near * t[None, :]).sum(axis=1) / np.maximum(near.sum(axis=1), 1)
    return Blobs(centres, full, tau)
