"""Differential-drive kinematics of an iRobot Create: wheel limits and exact arcs."""

from __future__ import annotations

import math

from agent.phase import wrap_pi

WHEEL_BASE_M = 0.26
MAX_WHEEL_SPEED = 0.5  # m/s, each wheel
_STRAIGHT = 1e-9  # |turn| below which an arc is integrated as a straight line


def limit_wheels(
    v: float, omega: float, wheel_base: float = WHEEL_BASE_M, max_wheel: float = MAX_WHEEL_SPEED
) -> tuple[float, float]:
    """(v, omega) scaled down so that neither wheel exceeds ``max_wheel``. Both wheels
    scale by the same factor, so the curvature omega / v (the path) is kept."""
    half = 0.5 * omega * wheel_base
    fastest = max(abs(v - half), abs(v + half))
    if fastest <= max_wheel:
        return v, omega
    scale = max_wheel / fastest
    return v * scale, omega * scale


def integrate_arc(
    x: float, y: float, theta: float, dist: float, dtheta: float
) -> tuple[float, float, float]:
    """Pose after driving ``dist`` along an arc that turns by ``dtheta`` (exact)."""
    if abs(dtheta) < _STRAIGHT:
        return x + dist * math.cos(theta), y + dist * math.sin(theta), wrap_pi(theta + dtheta)
    radius = dist / dtheta
    end = theta + dtheta
    return (
        x + radius * (math.sin(end) - math.sin(theta)),
        y - radius * (math.cos(end) - math.cos(theta)),
        wrap_pi(end),
    )


def step_pose(
    x: float, y: float, theta: float, v: float, omega: float, dt: float
) -> tuple[float, float, float]:
    """Pose after driving at constant (v, omega) for ``dt`` seconds (exact arc)."""
    return integrate_arc(x, y, theta, v * dt, omega * dt)
