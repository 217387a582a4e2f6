"""The distributed laws on a ring of neighbours: a closed edge of length L, robot i
owning the arc [s_i, s_{i+1}] (s_n = s_0 + L), its neighbours i - 1 and i + 1 mod n.

Every robot keeps its arc in its own frame of s, continuous in time (its ends may
leave [0, L): an arc over s = 0 is [L - a, L + b] or [-a, b], whichever it has come
to); two neighbours' frames differ by a whole number of L, which the two views of
their shared boundary tell. Both compute that boundary in the lower robot's frame
from the same published values, so they agree exactly, as on a chain (on a chain the
frames are one and every shift is 0: the chain's laws unchanged).

The team's agreement (agent.team) runs on the chain the ring holds once it is cut
between its highest live id and its lowest: chain maxima fed round a ring would come
back to their robot and never be forgotten, and the root's decision would travel
round for good. The phase consensus and the workload law use both neighbours.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from agent.partition import SegmentView, shared_boundary


def ring_neighbours(robot: int, live: Sequence[int]) -> tuple[int, int]:
    """The nearest live ids below and above ``robot`` round the ring of ``live`` (which
    holds it, and at least one other)."""
    ids = sorted(set(live))
    if robot not in ids or len(ids) < 2:
        raise ValueError(f"robot {robot} needs to be in a ring of at least two: {ids}")
    k = ids.index(robot)
    return ids[k - 1], ids[(k + 1) % len(ids)]


def chain_sides(robot: int, lower: int, upper: int) -> tuple[bool, bool]:
    """Which of a robot's two ring neighbours the team's chain (agent.team) runs
    through: the ring is cut between its highest id and its lowest, so the lowest
    robot is the chain's root (nothing below it) and the highest its top."""
    return lower < robot, upper > robot


def frame_shift(theirs: float, mine: float, length: float) -> float:
    """The whole number of ``length`` to add to a neighbour's s to put it in this
    robot's frame, from the two views (``theirs``, ``mine``) of one shared boundary."""
    return round((mine - theirs) / length) * length


def ring_shared_boundary(lower: SegmentView, upper: SegmentView, length: float,
                         k_s: float, min_len: float) -> float:
    """The new boundary of two ring neighbours, eq. 4.3, in the ``lower`` robot's frame:
    the upper's view moved into that frame by whole turns, then the chain's rule."""
    shift = frame_shift(upper.lo, lower.hi, length)
    moved = SegmentView(upper.lo + shift, upper.hi + shift, upper.workload)
    return shared_boundary(lower, moved, k_s, min_len)


def initial_arc(robot: int, team: int, length: float) -> tuple[float, float]:
    """Robot ``robot``'s share of equal arcs of a ring of ``team`` from s = 0."""
    if not 0 <= robot < team:
        raise ValueError(f"robot id {robot} outside a team of {team}")
    return robot * length / team, (robot + 1) * length / team


def ring_join_arc(lower: SegmentView | None, upper: SegmentView | None, length: float,
                  same: bool = False) -> tuple[float, float]:
    """The first claim of a robot that joins a running ring (a restart, or a new id)
    between its live neighbours, whose latest arcs are ``lower`` and ``upper`` (None: not
    heard yet), in the lower one's frame: the chain's rule (agent.partition.join_segment)
    round the ring, from the middle of the lower neighbour's arc to the middle of the
    upper one's, the upper's moved into that frame by the whole turns the gap between
    them tells (its lo nearest the lower's hi: right while the gap is under half the
    ring). Each neighbour then meets it halfway, so it starts with a quarter of each one's
    arc. A ring has no ends: a neighbour not heard is live, and the claim stops at the
    heard one's end on its side (the half of its arc next to the unheard robot).

    ``same``: one robot is both neighbours (it is the only other one): the claim is the
    upper third of its arc, and the two halfway meetings would leave the joiner a sixth
    of the ring when that robot owned all of it (from the middle, the claim's lower end
    would lie half a turn from that robot's upper end, where no one can tell the
    turns); the workload law moves the boundaries from there."""
    if lower is None and upper is None:
        raise ValueError("a join round a ring needs a neighbour heard (else: initial_arc)")
    if same:
        view = lower if lower is not None else upper
        assert view is not None
        return view.hi - (view.hi - view.lo) / 3.0, view.hi
    if lower is None:
        assert upper is not None
        return upper.lo, 0.5 * (upper.lo + upper.hi)
    if upper is None:
        return 0.5 * (lower.lo + lower.hi), lower.hi
    shift = frame_shift(upper.lo, lower.hi, length)
    lo = 0.5 * (lower.lo + lower.hi)
    hi = 0.5 * (upper.lo + upper.hi) + shift
    if not lo < hi:  # claims out of order: split what lies between them
        lo, hi = hi, lo
    if not lo < hi:  # their middles coincide: the chain's rule (join_segment), never empty
        lo, hi = 0.5 * (lower.lo + lo), 0.5 * (hi + upper.hi + shift)
    return lo, min(hi, lo + length)


def ring_update(boundaries: Sequence[float], workloads: Sequence[float], length: float,
                k_s: float, min_len: float) -> list[float]:
    """One step of eq. 4.3 for the whole ring (reference and tests): robot i's arc is
    [b_i, b_{i+1}], b_n = b_0 + length, and every boundary moves by K_s (Psi_i -
    Psi_{i-1}), limited as on the chain (``shared_boundary``) so no arc gets shorter
    than ``min_len``. Returns the new b_0..b_{n-1} (b_0 in robot n-1's frame less L)."""
    b = list(boundaries)
    n = len(b)
    if n < 2:
        raise ValueError("a ring needs at least two robots")
    out = []
    for i in range(n):
        below = (i - 1) % n
        lo_prev = b[below] - (length if i == 0 else 0.0)
        lower = SegmentView(lo_prev, b[i], workloads[below])
        upper = SegmentView(b[i], b[(i + 1) % n] + (length if i + 1 == n else 0.0),
                            workloads[i])
        out.append(shared_boundary(lower, upper, k_s, min_len))
    return out


def arc_lengths(boundaries: Sequence[float], length: float) -> list[float]:
    """Each robot's arc length from the ring's boundaries b_0..b_{n-1}."""
    n = len(boundaries)
    return [boundaries[(i + 1) % n] + (length if i + 1 == n else 0.0) - boundaries[i]
            for i in range(n)]


def ring_bins(length: float, bin_m: float) -> float:
    """The depth map's bin on a ring: ``bin_m`` stretched so that a whole number of
    bins make the ring, so a bin is the same bin in every robot's frame."""
    return length / max(1, math.floor(length / bin_m + 0.5))
