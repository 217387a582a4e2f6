"""Localisation error against truth (simulation only): the poses the agents were given
(the localizer's ``pf`` poses, or whatever source the run used) and, for the same run,
odometry alone, dead-reckoned here from the recorded Sense messages (each tick's
distance and turn, integrated as exact arcs from the true start pose, as the world's
own odometry pose is). Pure: a RunData in, arrays out."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from report.load import RunData, Truth


@dataclass
class LocErrors:
    """Position error (m) per robot at each of its truth samples (times ``t``)."""

    t: dict[int, np.ndarray] = field(default_factory=dict)
    pf: dict[int, np.ndarray] = field(default_factory=dict)  # the agents' poses
    odometry: dict[int, np.ndarray] = field(default_factory=dict)

    def pooled(self, which: str = "pf") -> np.ndarray:
        parts = list(getattr(self, which).values())
        return np.concatenate(parts) if parts else np.empty(0)


def dead_reckon(x0: float, y0: float, th0: float, dist: np.ndarray,
                dtheta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions after each step (dist, dtheta) along exact arcs; the first step is the
    start (its values are ignored: a tick's odometry is of the period before it)."""
    d = np.asarray(dist, dtype=float).copy()
    dth = np.asarray(dtheta, dtype=float).copy()
    if d.size:
        d[0] = dth[0] = 0.0
    th_after = th0 + np.cumsum(dth)
    th_before = th_after - dth
    straight = np.abs(dth) < 1e-9
    safe = np.where(straight, 1.0, dth)
    radius = d / safe
    dx = np.where(straight, d * np.cos(th_before), radius * (np.sin(th_after) - np.sin(th_before)))
    dy = np.where(straight, d * np.sin(th_before),
                  -radius * (np.cos(th_after) - np.cos(th_before)))
    return x0 + np.cumsum(dx), y0 + np.cumsum(dy)


def _error_at(track: Truth, t: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """|track - (x, y)| at each time of ``t`` (the truth's ticks) where the track has a
    sample at that very time; NaN elsewhere."""
    out = np.full(t.size, math.nan)
    if track.t.size == 0:
        return out
    idx = np.clip(np.searchsorted(track.t, t), 0, track.t.size - 1)
    same = np.isclose(track.t[idx], t, rtol=0.0, atol=1e-9)
    out[same] = np.hypot(track.x[idx[same]] - x[same], track.y[idx[same]] - y[same])
    return out


def localization_errors(run: RunData) -> LocErrors:
    """Errors of the given poses and of odometry alone against truth, per robot, on the
    truth's times (NaN where a robot had no pose at that time, and, where the world
    recorded its live agents, where the robot's agent was not in the team: a robot
    parked until it joins steers by no pose, whatever the localizer says of it)."""
    out = LocErrors()
    for rid, tr in sorted(run.truth.items()):
        if tr.t.size == 0:
            continue
        out.t[rid] = tr.t
        pose = run.poses.get(rid)
        if pose is not None and pose.t.size:
            out.pf[rid] = np.where(_in_team(run, rid, tr.t), _error_at(pose, tr.t, tr.x, tr.y),
                                   math.nan)
        odom = run.odometry.get(rid)
        if odom is not None and odom.shape[1]:
            ox, oy = dead_reckon(float(tr.x[0]), float(tr.y[0]), float(tr.theta[0]),
                                 odom[1], odom[2])
            track = Truth(odom[0], ox, oy, np.zeros_like(ox))
            out.odometry[rid] = _error_at(track, tr.t, tr.x, tr.y)
    return out


def _in_team(run: RunData, rid: int, t: np.ndarray) -> np.ndarray:
    """Whether robot ``rid``'s agent was live at each time of ``t``, by the world's
    ticks (everywhere True for a recording without them)."""
    if run.tick_t.size == 0 or len(run.tick_live) != run.tick_t.size:
        return np.ones(t.size, dtype=bool)
    live = np.array([rid in ids for ids in run.tick_live])
    idx = np.clip(np.searchsorted(run.tick_t, t - 1e-9), 0, run.tick_t.size - 1)
    return live[idx]


def summary_stats(errors: np.ndarray) -> tuple[float, float]:
    """Mean and 95th percentile, NaN ignored; NaN if there is nothing."""
    e = errors[np.isfinite(errors)] if errors.size else errors
    if e.size == 0:
        return math.nan, math.nan
    return float(e.mean()), float(np.percentile(e, 95))
