"""The stability bounds of DESIGN.md against the eigenvalues of the error maps."""

import math

import numpy as np
import pytest

from agent.stability import (
    check_gains,
    path_laplacian,
    phase_gain_bound,
    workload_gain_bound,
    workload_gain_bound_any,
    workload_matrix,
)


def spectral_radius(m: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(m))))


@pytest.mark.parametrize("n", range(2, 51))
def test_phase_bound_matches_eigenvalues(n):
    bound = phase_gain_bound(n)
    lap = path_laplacian(n)
    assert bound == pytest.approx(2.0 / np.max(np.linalg.eigvalsh(lap)), rel=1e-9)
    # The consensus mode (all phases equal) has eigenvalue 1 in I - K L; the phase
    # *errors* live on the other n - 1 modes, which must shrink inside the bound
    # and grow outside it.
    def error_radius(k):
        eig = np.linalg.eigvalsh(np.eye(n) - k * lap)
        return max(abs(e) for e in eig if not math.isclose(e, 1.0, abs_tol=1e-9))

    assert error_radius(0.999 * bound) < 1.0
    assert error_radius(1.001 * bound) > 1.0


def test_phase_bound_known_values():
    assert phase_gain_bound(3) == pytest.approx(2 / 3)  # the thesis's K_phi < 2/3
    assert phase_gain_bound(1000) == pytest.approx(0.5, abs=1e-5)
    assert all(phase_gain_bound(n) > 0.5 for n in range(2, 200))


def test_thesis_eq_4_9_for_three_robots():
    k = 0.4
    m = np.array([[1 - 2 * k, k], [k, 1 - 2 * k]])
    lap = path_laplacian(3)
    errors = np.array([[-1, 1, 0], [0, -1, 1]], dtype=float)
    # E_{t+1} = D (I - K L) Phi = M E_t for every Phi
    rng = np.random.default_rng(0)
    for _ in range(5):
        phi = rng.normal(size=3)
        assert np.allclose(errors @ (np.eye(3) - k * lap) @ phi, m @ (errors @ phi))


@pytest.mark.parametrize("n", [2, 3, 5, 10, 30])
def test_workload_bound_against_simulation(n):
    rng = np.random.default_rng(n)
    depths = rng.uniform(0.3, 1.8, size=n)
    bound = workload_gain_bound(depths)
    m = workload_matrix(depths)
    assert spectral_radius(np.eye(n - 1) - 0.99 * bound * m) < 1.0
    assert spectral_radius(np.eye(n - 1) - 1.01 * bound * m) > 1.0
    assert workload_gain_bound_any(depths.max()) <= bound + 1e-12


def test_workload_matrix_is_thesis_eq_4_4():
    d = [0.3, 1.5, 0.8]
    assert np.allclose(workload_matrix(d), [[1.8, -1.5], [-1.5, 2.3]])


def test_check_gains_refuses_outside():
    assert check_gains(3, 0.3, 0.02, 2.0) == []
    assert any("K_phi" in p for p in check_gains(3, 0.7, 0.02, 2.0))
    assert any("K_phi" in p for p in check_gains(50, 0.55, 0.02, 2.0))
    assert any("K_s" in p for p in check_gains(3, 0.3, 0.5, 2.0))
