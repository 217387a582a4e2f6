"""The localizer's identities against truth at every scan of a recorded run: each
robot's pose must be nearer its own true position than any other robot's."""

from __future__ import annotations

import numpy as np

from report.load import RunData


def truth_at_ticks(run: RunData, ids: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The ticks' times and every robot's true (x, y) at them, (robots, ticks, 2)."""
    t = run.truth[ids[0]].t
    return t, np.stack([np.stack([np.interp(t, run.truth[i].t, run.truth[i].x),
                                  np.interp(t, run.truth[i].t, run.truth[i].y)], axis=1)
                        for i in ids])


def check_identities(run: RunData, ids: list[int], min_poses: int, max_m: float,
                     mean_m: float) -> dict[int, float]:
    """Assert, for every robot of ``ids``, at least ``min_poses`` poses given at ticks,
    at each the robot's own truth nearest (no identity swapped), none more than
    ``max_m`` off, and a mean error at or under ``mean_m``; each robot's mean error."""
    t, truth = truth_at_ticks(run, ids)
    means = {}
    for n, i in enumerate(ids):
        pose = run.poses[i]
        at = np.searchsorted(t, pose.t)
        ok = (at < t.size) & (np.abs(t[np.minimum(at, t.size - 1)] - pose.t) < 1e-6)
        at, est = at[ok], np.stack([pose.x[ok], pose.y[ok]], axis=1)
        assert at.size >= min_poses, f"robot {i}: {at.size} poses at ticks"
        d = np.hypot(est[None, :, 0] - truth[:, at, 0], est[None, :, 1] - truth[:, at, 1])
        swapped = np.flatnonzero(d.argmin(axis=0) != n)
        assert swapped.size == 0, (f"robot {i} nearest another robot at "
                                   f"t = {t[at[swapped][:10]]}")
        assert d[n].max() < max_m, f"robot {i} off by {d[n].max():.3f} m"
        assert d[n].mean() <= mean_m, f"robot {i} mean error {d[n].mean():.4f} m"
        means[i] = float(d[n].mean())
    return means
