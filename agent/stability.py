"""Stability bounds of the two distributed laws for the actual chain (DESIGN.md).

Phase: the error map is I - K_phi L with L the path Laplacian of n robots, stable
for K_phi < 2 / lambda_max(L) = 2 / (2 + 2 cos(pi / n)).
Workload: the error map is I - K_s M(d) (thesis eq. 4.4) with M the depth-weighted
chain matrix, stable for K_s < 2 / lambda_max(M).
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


def check_gains(n: int, k_phi: float, k_s: float, max_depth: float) -> list[str]:
    """Reasons the gains are unstable for a chain of ``n`` robots; empty if stable."""
    problems = []
    bound = phase_gain_bound(n)
    if not 0.0 < k_phi < bound:
        problems.append(
            f"K_phi = {k_phi} is outside the stable range (0, {bound:.4f}) for a chain of {n}"
        )
    ks_bound = workload_gain_bound_any(max_depth)
    if not 0.0 < k_s < ks_bound:
        problems.append(
            f"K_s = {k_s} is outside (0, {ks_bound:.4f}), stable for depths up to {max_depth} m"
        )
    return problems
