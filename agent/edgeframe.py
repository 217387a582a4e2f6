"""A closed edge as a frame of coordinates: arc length s along its contour, signed
distance d across it (positive into the ice), heading psi relative to its tangent.

The contour is a closed polyline drawn counterclockwise, so that the ice lies on the
left of its tangent: the open edge's convention (s along +x, ice for y > 0) holds
locally everywhere on it. A robot's pose in this frame is what the patrol and the
phase law steer by on a closed edge (agent.ring); its curvature command comes back
to the world through the frame's curvature (``world_omega``). Pure Python, no numpy:
an agent never needs it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from agent.phase import wrap_pi

# A robot's projection walks from its last foot along the polyline at most this many
# vertices a tick; more means it was carried (or first placed) and a full search runs.
MAX_WALK = 400
# 1 - kappa d, the ratio of a parallel curve's length to the contour's, is held above
# this where it would vanish (a robot as deep as the contour's radius of curvature):
# the frame is singular there, and the patrol never goes so deep on a map we accept.
MIN_STRETCH = 0.2


class ClosedEdge:
    """A closed, counterclockwise polyline (the last vertex joins the first) with the
    arc length ``s`` of each vertex, its length ``length``, the tangent's direction at
    each vertex and a curvature per piece."""

    def __init__(self, points: Sequence[tuple[float, float]]) -> None:
        pts = [(float(x), float(y)) for x, y in points]
        if len(pts) < 3:
            raise ValueError("a closed edge needs at least three vertices")
        if not all(math.isfinite(v) for p in pts for v in p):
            raise ValueError("a closed edge's vertices must be finite")
        area2 = sum(pts[j - 1][0] * pts[j][1] - pts[j][0] * pts[j - 1][1]
                    for j in range(len(pts)))
        if area2 <= 0.0:
            raise ValueError("a closed edge must run counterclockwise (ice on its left)")
        n = len(pts)
        seg = [math.dist(pts[j], pts[(j + 1) % n]) for j in range(n)]
        if min(seg) <= 0.0:
            raise ValueError("a closed edge has two equal consecutive vertices")
        self.points = pts
        self.n = n
        self.seg_len = seg
        self.s: list[float] = [0.0] * n
        for j in range(1, n):
            self.s[j] = self.s[j - 1] + seg[j - 1]
        self.length = self.s[-1] + seg[-1]
        # each piece's own direction, and the vertex tangent (the chord of its two
        # neighbours), whose turning along a piece is its curvature
        self.piece_angle = [math.atan2(pts[(j + 1) % n][1] - pts[j][1],
                                       pts[(j + 1) % n][0] - pts[j][0]) for j in range(n)]
        self.vertex_angle = [self.piece_angle[j - 1]
                             + 0.5 * wrap_pi(self.piece_angle[j] - self.piece_angle[j - 1])
                             for j in range(n)]
        self._last: tuple[float, tuple[int, float]] = (math.nan, (0, 0.0))
        self.curvature = [wrap_pi(self.vertex_angle[(j + 1) % n] - self.vertex_angle[j])
                          / seg[j] for j in range(n)]

    # along the contour --------------------------------------------------------------
    def wrap(self, s: float) -> float:
        """s wrapped into [0, length)."""
        w = math.fmod(s, self.length)
        if w < 0.0:
            w += self.length
        return 0.0 if w >= self.length else w

    def piece(self, s: float) -> tuple[int, float]:
        """The piece holding arc length ``s`` (any real: it wraps) and how far into it,
        as a fraction."""
        if s == self._last[0]:  # a tick asks of one s several times
            return self._last[1]
        found = self._piece(s)
        self._last = (s, found)
        return found

    def _piece(self, s: float) -> tuple[int, float]:
        w = self.wrap(s)
        lo, hi = 0, self.n - 1
        while lo < hi:  # the last vertex at or before w
            mid = (lo + hi + 1) // 2
            if self.s[mid] <= w:
                lo = mid
            else:
                hi = mid - 1
        return lo, min(1.0, max(0.0, (w - self.s[lo]) / self.seg_len[lo]))

    def point(self, s: float) -> tuple[float, float]:
        j, f = self.piece(s)
        (x0, y0), (x1, y1) = self.points[j], self.points[(j + 1) % self.n]
        return x0 + f * (x1 - x0), y0 + f * (y1 - y0)

    def tangent_angle(self, s: float) -> float:
        """Direction of the tangent at s, rad: the vertex tangents interpolated."""
        j, f = self.piece(s)
        a0 = self.vertex_angle[j]
        return wrap_pi(a0 + f * wrap_pi(self.vertex_angle[(j + 1) % self.n] - a0))

    def curvature_at(self, s: float) -> float:
        """Signed curvature at s, 1/m: positive where the edge bends towards the ice."""
        return self.curvature[self.piece(s)[0]]

    def at(self, s: float, d: float) -> tuple[float, float]:
        """The world point at arc length s and distance d into the ice (the left
        normal), as the frame maps it."""
        x, y = self.point(s)
        a = self.tangent_angle(s)
        return x - d * math.sin(a), y + d * math.cos(a)

    # from the world ------------------------------------------------------------------
    def _foot(self, j: int, x: float, y: float) -> tuple[float, float]:
        """Squared distance to piece j and the fraction along it of the nearest point."""
        (x0, y0), (x1, y1) = self.points[j], self.points[(j + 1) % self.n]
        dx, dy = x1 - x0, y1 - y0
        f = ((x - x0) * dx + (y - y0) * dy) / (dx * dx + dy * dy)
        f = min(1.0, max(0.0, f))
        px, py = x0 + f * dx - x, y0 + f * dy - y
        return px * px + py * py, f

    def project(self, x: float, y: float, hint: float | None = None) -> tuple[float, float]:
        """(s, d) of a world point: the nearest point of the contour, found from
        ``hint`` (the last s) by walking along the polyline while the distance falls, so
        a robot's s is continuous where two parts of the contour are about as near (a
        leg deep under a narrow floe); without a hint, or if the walk runs too far, the
        nearest over the whole contour. d is positive on the ice side."""
        if hint is None:
            best = min(range(self.n), key=lambda k: self._foot(k, x, y)[0])
        else:
            best = self.piece(hint)[0]
            dist = self._foot(best, x, y)[0]
            for step in (1, -1):
                j, walked = best, 0
                while walked < MAX_WALK:
                    k = (j + step) % self.n
                    dk = self._foot(k, x, y)[0]
                    if dk > dist:
                        break
                    j, dist, walked = k, dk, walked + 1
                best = j if walked else best
                if walked:
                    break
            if walked >= MAX_WALK:
                return self.project(x, y, None)
        j, f = best, self._foot(best, x, y)[1]
        # The polyline's own foot is off the frame's normal (its tangent turns along a
        # piece) by up to half a piece's turn, a few mm of s a metre in: move the foot
        # along the piece until the point lies on the interpolated normal (Newton).
        for _ in range(6):
            (x0, y0), (x1, y1) = self.points[j], self.points[(j + 1) % self.n]
            turn = wrap_pi(self.vertex_angle[(j + 1) % self.n] - self.vertex_angle[j])
            a = self.vertex_angle[j] + f * turn
            px, py = x0 + f * (x1 - x0) - x, y0 + f * (y1 - y0) - y
            along = -(px * math.cos(a) + py * math.sin(a))
            d = px * math.sin(a) - py * math.cos(a)
            slope = -self.seg_len[j] * math.cos(a - self.piece_angle[j]) + d * turn
            if slope >= 0.0:
                break
            move = -along / slope
            f += move
            if f < 0.0:
                j, f = (j - 1) % self.n, 1.0
            elif f > 1.0:
                j, f = (j + 1) % self.n, 0.0
            elif abs(move) < 1e-9:
                break
        (x0, y0), (x1, y1) = self.points[j], self.points[(j + 1) % self.n]
        s = self.s[j] + f * self.seg_len[j]
        a = self.tangent_angle(s)
        px, py = x0 + f * (x1 - x0), y0 + f * (y1 - y0)
        d = -(x - px) * math.sin(a) + (y - py) * math.cos(a)
        return self.wrap(s), d

    def to_edge(self, x: float, y: float, theta: float, hint: float | None = None
                ) -> tuple[float, float, float]:
        """A world pose as (s, d, psi): psi the heading from the local tangent."""
        s, d = self.project(x, y, hint)
        return s, d, wrap_pi(theta - self.tangent_angle(s))

    def stretch(self, s: float, d: float) -> float:
        """1 - kappa d: how much shorter a line at distance d into the ice runs than
        the contour beside it (held at MIN_STRETCH where the frame turns singular)."""
        return max(MIN_STRETCH, 1.0 - self.curvature_at(s) * d)

    def world_omega(self, v: float, omega_edge: float, s: float, d: float, psi: float
                    ) -> float:
        """The world turn rate for a patrol that steers in the frame as if it were flat.
        In the frame s' = v cos psi / (1 - kappa d) and psi' = omega - kappa s'; with
        omega = (omega_edge + kappa v cos psi) / (1 - kappa d) the heading in the frame
        turns at omega_edge / (1 - kappa d), so that ds/dpsi = cos psi / curvature: the
        path's extent along s is the patrol's own (an arc lands on the next pass line,
        deep under a bend or out beyond one), only stretched across it by the frame. A
        leg along the normal (cos psi = 0, no turn) is a straight line in the world."""
        return ((omega_edge + self.curvature_at(s) * v * math.cos(psi))
                / self.stretch(s, d))
