"""Workload balance: the boundary update of thesis eq. 4.1-4.3, for a whole chain
(reference and tests) and as the distributed rule each agent applies to the
boundary it shares with one neighbour."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class SegmentView:
    """What a robot has published about its segment at the previous tick."""

    lo: float
    hi: float
    workload: float


def chain_update(
    boundaries: Sequence[float], workloads: Sequence[float], k_s: float, min_len: float
) -> list[float]:
    """S_{t+1} = S_t + U_s (eq. 4.1, 4.3): each inner boundary moves by
    K_s (Psi_{i+1} - Psi_i), the ends stay. Each move is limited to half the slack
    of both segments beside it, so no segment gets shorter than ``min_len``."""
    s = list(boundaries)
    out = list(s)
    for j in range(1, len(s) - 1):
        lower = SegmentView(s[j - 1], s[j], workloads[j - 1])
        upper = SegmentView(s[j], s[j + 1], workloads[j])
        out[j] = shared_boundary(lower, upper, k_s, min_len)
    return out


def shared_boundary(
    lower: SegmentView, upper: SegmentView, k_s: float, min_len: float
) -> float:
    """The new boundary between two neighbouring robots, eq. 4.3.

    Both neighbours evaluate this on the same published values and so agree on the
    result without a further exchange. Where their views of the boundary differ (a
    robot between them left), they meet in the middle of the gap.
    """
    ref, down_room, up_room = _rooms(lower, upper, min_len)
    move = k_s * (upper.workload - lower.workload)
    return ref + min(max(move, -down_room), up_room)


def _rooms(lower: SegmentView, upper: SegmentView, min_len: float
           ) -> tuple[float, float, float]:
    """The middle of two neighbours' views of their boundary, and how far it may move
    down and up: half the slack of the segment on that side."""
    ref = 0.5 * (lower.hi + upper.lo)
    down_room = max(0.0, 0.5 * (ref - lower.lo - min_len))
    up_room = max(0.0, 0.5 * (upper.hi - ref - min_len))
    return ref, down_room, up_room


def boundary_reach(lower: SegmentView, upper: SegmentView, min_len: float
                   ) -> tuple[float, float]:
    """Where ``shared_boundary`` can put the boundary of two neighbours, whatever their
    workloads: from the middle of their two views of it, at most half the slack of
    either segment beside it (so neither gets shorter than ``min_len``)."""
    ref, down_room, up_room = _rooms(lower, upper, min_len)
    return ref - down_room, ref + up_room


def join_segment(
    lower: SegmentView | None, upper: SegmentView | None, edge_lo: float, edge_hi: float,
    *, lower_unheard: bool = False, upper_unheard: bool = False,
) -> tuple[float, float]:
    """The first claim of a robot that joins a running team (a restart, or a new id)
    between live neighbours ``lower`` and ``upper`` (None at an end of the chain): from
    the middle of the lower neighbour's segment to the middle of the upper one's. Each
    neighbour then meets it halfway (``shared_boundary``), so it starts with a quarter
    of each neighbour's segment and workload balance evens the rest out; no robot
    restarts. With no neighbour heard it claims the whole edge.

    A side whose neighbour is alive but not heard (``lower_unheard``/``upper_unheard``,
    its view None) is not an end of the chain: the claim stops at the heard neighbour's
    far boundary on that side (the half of its segment next to the unheard robot), so it
    never runs past a live robot to the end of the edge."""
    lo = edge_lo if lower is None else 0.5 * (lower.lo + lower.hi)
    hi = edge_hi if upper is None else 0.5 * (upper.lo + upper.hi)
    if lower is None and lower_unheard and upper is not None:
        # (halfway to the middle if the upper one claims down to the end: no live robot
        # below it should, but the bus may say so)
        lo = upper.lo if upper.lo > edge_lo else 0.5 * (upper.lo + hi)
    if upper is None and upper_unheard and lower is not None:
        hi = lower.hi if lower.hi < edge_hi else 0.5 * (lo + lower.hi)
    if not lo < hi:  # neighbours' claims out of order: split what lies between them
        lo, hi = min(lo, hi), max(lo, hi)
    if not lo < hi and lower is not None and upper is not None:
        # their middles coincide (both claim the same stretch, as no two live robots
        # should): from the middle of the lower's lower half to the middle of the upper's
        # upper half, never an empty segment nor one past a neighbour
        lo, hi = 0.5 * (lower.lo + lo), 0.5 * (hi + upper.hi)
    return lo, hi
