"""The particle filter's two models, as nav2's AMCL gives its filter a motion model and
a sensor model: the odometry's noise (thesis eq. 5.2) and the likelihood of a measured
centre (eq. 5.3). Pure: arrays in, arrays out; the random numbers come from the
Generator the filter passes in."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class OdometryMotion:
    """A period's odometry (distance, turn) moves every particle along an arc at its
    mid heading, with Gaussian noise whose std grows with the distance and the turn
    (and a floor, so a robot standing still still spreads a little)."""

    dist_frac: float = 0.05  # std of driven distance per metre driven
    dist_floor_m: float = 0.002  # std of driven distance per period
    turn_frac: float = 0.05  # std of turn per radian turned
    turn_per_m: float = 0.05  # std of turn per metre driven, rad/m
    turn_floor_rad: float = 0.004  # std of turn per period

    def sample(self, x: np.ndarray, y: np.ndarray, theta: np.ndarray, dist: np.ndarray,
               dtheta: np.ndarray, rng: np.random.Generator
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """New (x, y, theta) of particles of shape (robots, particles) after each
        robot's odometry (shape (robots,)). Theta is left unwrapped: only its sine and
        cosine are ever used."""
        dist = np.asarray(dist, dtype=float)[:, None]
        dtheta = np.asarray(dtheta, dtype=float)[:, None]
        sd = self.dist_frac * np.abs(dist) + self.dist_floor_m
        st = (self.turn_frac * np.abs(dtheta) + self.turn_per_m * np.abs(dist)
              + self.turn_floor_rad)
        noise = rng.standard_normal((2, *x.shape))
        d = dist + sd * noise[0]
        dt = dtheta + st * noise[1]
        mid = theta + 0.5 * dt
        return x + d * np.cos(mid), y + d * np.sin(mid), theta + dt


@dataclass(frozen=True)
class CentreSensor:
    """The scan's measured centre of a robot, Gaussian about the true one with
    ``std_m`` per axis."""

    std_m: float = 0.02

    def log_likelihood(self, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Log likelihood (up to a constant) of particles (rows, particles) given one
        measured centre per row (z, shape (rows, 2))."""
        dx = x - z[:, 0:1]
        dy = y - z[:, 1:2]
        return -(dx * dx + dy * dy) / (2.0 * self.std_m**2)
