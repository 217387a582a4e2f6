"""Stability bounds of the two distributed laws for the actual chain (DESIGN.md).

Phase: the error map is I - K_phi L with L the path Laplacian of n robots, stable
for K_phi < 2 / lambda_max(L) = 2 / (2 + 2 cos(pi / n)).
Workload: the error map is I - K_s M(d) (thesis eq. 4.4) with M the depth-weighted
chain matrix, stable for K_s < 2 / lambda_max(M).
On a ring (a closed edge: robot n-1 and robot 0 are neighbours too) L is the cycle's
Laplacian, eigenvalues 2 - 2 cos(2 pi k / n), so K_phi < 2 / (2 - 2 cos(2 pi floor(n/2)
/ n)): 2/3 for n = 3, 1/2 for every even n; M gains the pair (n-1, 0), and Gershgorin's
4 d_max bounds it as it bounds the chain's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the matrices import numpy when built: an agent's check needs none
    import numpy as np


def path_laplacian(n: int) -> np.ndarray:
    import numpy as np

    if n < 1:
        raise ValueError("a chain needs at least one robot")
    lap = np.zeros((n, n))
    for i in range(n - 1):
        lap[i, i] += 1.0
        lap[i + 1, i + 1] += 1.0
        lap[i, i + 1] = lap[i + 1, i] = -1.0
    return lap


def phase_gain_bound(n: int) -> float:
    """Largest stable K_phi (exclusive) for a chain of ``n`` robots; 2/3 for n = 3."""
    if n < 2:
        return math.inf
    return 2.0 / (2.0 + 2.0 * math.cos(math.pi / n))


def ring_laplacian(n: int) -> np.ndarray:
    """The Laplacian of a ring of ``n`` robots, the cycle graph. A ring of two is each
    robot's lower and upper neighbour at once, so the pair counts twice (the consensus
    term pulls with both sides), as the formula's 2 - 2 cos(pi) = 4 says."""
    import numpy as np

    if n < 2:
        raise ValueError("a ring needs at least two robots")
    lap = np.zeros((n, n))
    for i in range(n):
        j = (i + 1) % n
        lap[i, i] += 1.0
        lap[j, j] += 1.0
        lap[i, j] -= 1.0
        lap[j, i] -= 1.0
    return lap


def ring_phase_gain_bound(n: int) -> float:
    """Largest stable K_phi (exclusive) for a ring of ``n`` robots: 2 / lambda_max of the
    cycle's Laplacian, lambda_k = 2 - 2 cos(2 pi k / n) at k = floor(n / 2)."""
    if n < 2:
        return math.inf
    return 2.0 / (2.0 - 2.0 * math.cos(2.0 * math.pi * (n // 2) / n))


def ring_workload_matrix(depths: Sequence[float]) -> np.ndarray:
    """M of e_Psi(t+1) = (I - K_s M) e_Psi(t) on a ring, e_i = Psi_{i+1} - Psi_i for
    i = 0..n-1 (indices mod n): the boundary between i and i+1 moves by K_s e_i."""
    import numpy as np

    d = list(depths)
    n = len(d)
    mat = np.zeros((n, n))
    for i in range(n):
        mat[i, i] += d[i] + d[(i + 1) % n]
        mat[i, (i + 1) % n] -= d[(i + 1) % n]
        mat[i, (i - 1) % n] -= d[i]
    return mat


def ring_workload_gain_bound(depths: Sequence[float]) -> float:
    """Largest stable K_s (exclusive) on a ring with these depths: the sum of the
    errors round the ring is always 0 (1^T M = 0), and on that subspace the map is
    I - K_s M, stable for K_s < 2 / lambda_max(M)."""
    import numpy as np

    if len(depths) < 2:
        return math.inf
    lam = float(np.max(np.real(np.linalg.eigvals(ring_workload_matrix(depths)))))
    return 2.0 / lam


def workload_matrix(depths: Sequence[float]) -> np.ndarray:
    """M of e_Psi(t+1) = (I - K_s M) e_Psi(t) for average depths d_0..d_{n-1}."""
    import numpy as np

    d = list(depths)
    m = len(d) - 1
    mat = np.zeros((m, m))
    for i in range(m):
        mat[i, i] = d[i] + d[i + 1]
        if i + 1 < m:
            mat[i, i + 1] = -d[i + 1]
        if i > 0:
            mat[i, i - 1] = -d[i]
    return mat


def workload_gain_bound(depths: Sequence[float]) -> float:
    """Largest stable K_s (exclusive) for these depths (thesis eq. 4.4)."""
    import numpy as np

    if len(depths) < 2:
        return math.inf
    lam = float(np.max(np.real(np.linalg.eigvals(workload_matrix(depths)))))
    return 2.0 / lam


def workload_gain_bound_any(max_depth: float) -> float:
    """A bound on K_s valid for any chain length whose depths are at most
    ``max_depth`` (Gershgorin: lambda_max(M) <= 4 max d)."""
    return 2.0 / (4.0 * max_depth)


def check_gains(n: int, k_phi: float, k_s: float, max_depth: float, closed: bool = False
                ) -> list[str]:
    """Reasons the gains are unstable for a chain (or, ``closed``, a ring) of ``n``
    robots; empty if stable."""
    problems = []
    bound = ring_phase_gain_bound(n) if closed else phase_gain_bound(n)
    shape = "ring" if closed else "chain"
    if not 0.0 < k_phi < bound:
        problems.append(
            f"K_phi = {k_phi} is outside the stable range (0, {bound:.4f}) for a {shape} of {n}"
        )
    ks_bound = workload_gain_bound_any(max_depth)
    if not 0.0 < k_s < ks_bound:
        problems.append(
            f"K_s = {k_s} is outside (0, {ks_bound:.4f}), stable for depths up to {max_depth} m"
        )
    return problems
