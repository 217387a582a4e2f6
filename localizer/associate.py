"""The localizer's data association: which measured centre is which robot's, and which
free blob a lost robot may be re-seeded on. Pure functions of predictions, centres and
what each robot's odometry did."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment


def assign(predicted: np.ndarray, candidates: np.ndarray, active: np.ndarray,
           gate_m: float | np.ndarray) -> np.ndarray:
    """For each robot, the index of its measured centre, or -1: minimum total squared
    distance over robots in ``active``, each pair gated at ``gate_m`` (one gate, or one
    per candidate)."""
    out = np.full(predicted.shape[0], -1, dtype=int)
    rows = np.flatnonzero(active)
    if rows.size == 0 or candidates.shape[0] == 0:
        return out
    d2 = ((predicted[rows, None, :] - candidates[None, :, :]) ** 2).sum(axis=2)
    big = 1e6
    if np.ndim(gate_m):
        gates = np.asarray(gate_m, dtype=float)[None, :]
        cost = np.where(d2 <= gates * gates, d2, big)
    else:
        cost = np.where(d2 <= gate_m * gate_m, d2, big)
    r_idx, c_idx = linear_sum_assignment(cost)
    ok = cost[r_idx, c_idx] < big
    out[rows[r_idx[ok]]] = c_idx[ok]
    return out


@dataclass(frozen=True)
class Recovery:
    """How lost robots are matched to free blobs (``recovery``)."""

    lost_after: int = 3  # scans without a measurement before a free blob may re-seed
    # A lost robot may re-seed on a free blob this far from its prediction, and this much
    # farther per scan it has been lost: an occluded robot does not jump to a stranger
    # across the scene, a kidnapped one is found within a few scans of its new place.
    reach_m: float = 0.25
    growth_m: float = 0.1
    # A free blob that stood still (within still_m) over the last still_scans scans is
    # not a robot whose odometry says it drove more than moved_m meanwhile (a robot
    # parked in view, waiting to join, is no lost robot that is driving).
    still_scans: int = 10
    still_m: float = 0.02
    moved_m: float = 0.05
    # A robot's blob, one it is tracking and that has not yet carried it ``confirm_m``
    # from where its filter was seeded, that stood within ``held_still_m`` over the last
    # ``held_scans`` scans while its odometry drove more than ``held_moved_m`` is not its:
    # it took a parked robot's blob (at the start, hidden behind it) and is released
    # (lost, to be found on a blob that moves). 0: not checked.
    confirm_m: float = 0.1
    held_scans: int = 4
    held_still_m: float = 0.01
    held_moved_m: float = 0.02
    # A free blob followed back through those scans (the nearest centre within
    # follow_m each scan) that moved faster than this is no robot (a Create's top speed
    # is 0.5 m/s): a person walking through the team, whose legs can look like one, does
    # not take an occluded robot's track. 0: not checked (the ideal laser: no people).
    top_speed_m_s: float = 0.0
    follow_m: float = 0.25


def still_blobs(centres: np.ndarray, recent: Sequence[np.ndarray], still_m: float
                ) -> np.ndarray:
    """For each centre of this scan, whether a centre lay within ``still_m`` of it in
    every one of the ``recent`` scans' centres (this scan's among them)."""
    out = np.full(centres.shape[0], True)
    for earlier in recent:
        if not out.any():
            break
        if earlier.shape[0] == 0:
            return np.zeros(centres.shape[0], dtype=bool)
        d = np.hypot(centres[:, None, 0] - earlier[None, :, 0],
                     centres[:, None, 1] - earlier[None, :, 1])
        out &= d.min(axis=1) <= still_m
    return out


def fast_blobs(centres: np.ndarray, recent: Sequence[np.ndarray], follow_m: float,
               speed_m_s: float, scan_s: float) -> np.ndarray:
    """For each centre of this scan (the last of ``recent``), whether it can be followed
    back through every earlier scan of ``recent`` (each time to the nearest centre, if
    within ``follow_m``) to a place farther than ``speed_m_s`` times the time between.
    One that cannot be followed (a blob that came into view, a robot set down
    elsewhere) is not fast."""
    out = np.zeros(centres.shape[0], dtype=bool)
    earlier = list(recent)[:-1]
    if not earlier or centres.shape[0] == 0 or scan_s <= 0:
        return out
    for j in range(centres.shape[0]):
        at = centres[j]
        for scan in reversed(earlier):
            if scan.shape[0] == 0:
                break
            d = np.hypot(scan[:, 0] - at[0], scan[:, 1] - at[1])
            k = int(np.argmin(d))
            if d[k] > follow_m:
                break
            at = scan[k]
        else:
            out[j] = float(np.hypot(*(centres[j] - at))) > speed_m_s * scan_s * len(earlier)
    return out


def recovery(centres: np.ndarray, used: np.ndarray, predicted: np.ndarray,
             started: np.ndarray, missed: np.ndarray, still: np.ndarray | None,
             moved: np.ndarray, rules: Recovery, fast: np.ndarray | None = None,
             scan_s: float = 0.0) -> list[tuple[int, int]]:
    """Which lost robot is re-seeded on which free blob (centres not ``used``), as
    (robot, centre index) pairs.

    With nobody started, robots take the blobs in the order of the edge (robot 0
    leftmost, the order of the team's initial segments). Otherwise the robots that had
    a pose and went unmeasured take the free blobs nearest their predictions first
    (pairs by distance over all of them, not robot by robot), each within its reach
    (``reach_m`` plus ``growth_m`` per scan unmeasured); one unmeasured for fewer
    scans than ``lost_after`` only holds the blob it is nearest, without re-seeding.
    Robots never seeded take what is left in the order of the edge. ``still`` (None
    while too few scans tell) marks the blobs that stood still; ``moved``, the robots
    whose odometry drove: a blob that stood still is no robot that drove, and one that
    moved is no robot never seeded whose wheels stood (one parked, waiting to join). A
    robot with a pose may take a moving blob though its odometry stood (its wheels may
    be what failed), but with ``top_speed_m_s`` set only within what it can drive in
    ``lost_after`` scans of its reach (``scan_s`` the time between scans); and none takes
    one ``fast`` marks (faster than a robot drives)."""
    lost = np.flatnonzero(~started | (missed >= rules.lost_after))
    free = [j for j in range(centres.shape[0]) if not used[j]]
    if lost.size == 0 or not free:
        return []
    if not started.any():
        order = sorted(free, key=lambda j: float(centres[j, 0]))
        return list(zip(lost.tolist(), order, strict=False))

    def fits(robot: int, j: int) -> bool:
        if fast is not None and fast[j]:
            return False
        if still is None:
            return True
        if still[j]:
            return not moved[robot]
        return bool(started[robot] or moved[robot])

    pairs = []
    speed = rules.top_speed_m_s * scan_s  # m a scan
    for robot in np.flatnonzero(started & (missed > 0)).tolist():
        grown = rules.reach_m + rules.growth_m * float(missed[robot])
        for j in free:
            d = float(np.hypot(*(centres[j] - predicted[robot])))
            # A moving blob for a robot whose wheels stood only near its prediction: one
            # whose wheels failed drives out of its gate in view and is re-seeded within
            # the scans that take (``lost_after``), at most at its top speed. Further
            # off it is someone walking past a robot that stands hidden (a robot carried
            # off and set down stands still, or drives). Known once the top speed is.
            reach = grown
            if (speed and still is not None and not still[j] and not moved[robot]):
                reach = min(grown, rules.reach_m + speed * rules.lost_after)
            if d <= reach and fits(robot, j):
                pairs.append((d, robot, j))
    out: list[tuple[int, int]] = []
    taken: set[int] = set()
    for _, robot, j in sorted(pairs):
        if robot in taken or j not in free:
            continue
        free.remove(j)
        taken.add(robot)
        if missed[robot] >= rules.lost_after:
            out.append((robot, j))
    for robot in lost[~started[lost]].tolist():
        fitting = [j for j in free if fits(robot, j)]
        if fitting:
            j = min(fitting, key=lambda j: float(centres[j, 0]))
            free.remove(j)
            out.append((robot, j))
    return out


def held_wrongly(match: np.ndarray, centres: np.ndarray, recent: Sequence[np.ndarray],
                 drove: np.ndarray, rules: Recovery) -> np.ndarray:
    """The robots whose assigned centre (``match``, -1 for none) stood within
    ``held_still_m`` over ``recent`` (the last ``held_scans`` scans' centres, this one's
    among them) while their odometry drove (``drove``, metres between the first of those
    scans and this one) more than ``held_moved_m``: a blob that stood still is not a
    robot that drove."""
    out = np.zeros(match.shape[0], dtype=bool)
    if rules.held_moved_m <= 0 or len(recent) < rules.held_scans:
        return out
    rows = np.flatnonzero((match >= 0) & (drove > rules.held_moved_m))
    if rows.size:
        still = still_blobs(centres[match[rows]], recent, rules.held_still_m)
        out[rows[still]] = True
    return out
