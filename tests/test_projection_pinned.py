"""The physically consistent projection (adaptive_mj.laws.pseudo_inertia) pinned with independent numbers (issue 54):
the pseudo-inertia of bodies written out by hand, its eigenvalues against numpy's LAPACK, the objective's gradient
against central finite differences of an objective written here, the projection's optimum against scipy's generic
solver (over X = L Lᵀ, PSD by construction), and the step and momentum against the Hessian's eigenvalues derived
by hand. Edge cases by name: a point mass (a pseudo-inertia of rank one: smallest eigenvalue 0, on the edge of the
set), a tolerance met exactly. No MuJoCo (tools/mutate.py runs this file for pseudo_inertia)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize

from adaptive_mj.laws import pseudo_inertia as pi


def _theta(m, c, inertia):
    """π = [m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] from a mass, its centre and its inertia about the
    origin, by hand."""
    return np.array([m, m * c[0], m * c[1], m * c[2], inertia[0][0], inertia[0][1], inertia[1][1], inertia[0][2],
                     inertia[1][2], inertia[2][2]], dtype=float)


def _params_of_X(X):
    """π(X) written out here: m = X₃₃, h = X[0:3, 3], I = tr(Σ)·1 − Σ with Σ = X[0:3, 0:3]."""
    S = X[:3, :3]
    inertia = np.trace(S) * np.eye(3) - S
    return np.array([X[3, 3], X[0, 3], X[1, 3], X[2, 3], inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2],
                     inertia[1, 2], inertia[2, 2]])


def _objective(X, target, gamma):
    r = _params_of_X(X) - target
    return 0.5 * float(np.sum(gamma * r * r))


def test_the_constants_are_the_documented_ones():
    assert pi.BODY_FIELDS == 13 and pi.PSD_TOLERANCE == 1e-12
    assert pi.STEP_TOLERANCE == 1e-14 and pi.MAX_ITERATIONS == 400


def test_a_point_mass_s_pseudo_inertia_by_hand_is_on_the_edge_of_the_set():
    """m = 2 kg at c = (1, 2, 3) m: I = m(|c|²·1 − c cᵀ) about the origin, J = m [c; 1][c; 1]ᵀ: rank one."""
    theta = _theta(2.0, (1.0, 2.0, 3.0), [[26.0, -4.0, -6.0], [-4.0, 20.0, -12.0], [-6.0, -12.0, 10.0]])
    J = np.empty((4, 4))
    pi.pseudo_inertia(theta, 0, J)
    expected = 2.0 * np.outer([1.0, 2.0, 3.0, 1.0], [1.0, 2.0, 3.0, 1.0])
    np.testing.assert_array_equal(J, expected)
    lam = pi.eigenvalues(theta, (0,))
    assert lam.shape == (4,) if lam.ndim == 1 else lam.shape == (1, 4)
    np.testing.assert_allclose(np.ravel(lam), [0.0, 0.0, 0.0, 30.0], atol=1e-12)  # m (|c|² + 1) = 30
    lo, total = pi.smallest_eigenvalue(J)
    assert abs(lo) <= 1e-12 and total == pytest.approx(30.0, rel=1e-12)
    assert pi.is_physical(lo, total)
    record = pi.body_record((0,), np.full(10, 0.5))
    kept = theta.copy()
    assert not pi.project_body(kept, 0, record[2], record[3], record[4:14])
    np.testing.assert_array_equal(kept, theta)


def test_a_body_at_an_offset_reads_its_own_ten_parameters():
    theta = np.concatenate(([9.0, 9.0], _theta(1.0, (0.0, 0.0, 0.5), [[0.3, 0.01, 0.02], [0.01, 0.4, 0.03],
                                                                     [0.02, 0.03, 0.1]])))
    J = np.empty((4, 4))
    pi.pseudo_inertia(theta, 2, J)
    # Σ = ½ tr(I)·1 − I with ½ tr(I) = 0.4
    expected = np.array([[0.1, -0.01, -0.02, 0.0], [-0.01, 0.0, -0.03, 0.0], [-0.02, -0.03, 0.3, 0.5],
                         [0.0, 0.0, 0.5, 1.0]])
    np.testing.assert_allclose(J, expected, rtol=0, atol=1e-15)
    back = np.full(12, 7.0)
    pi.parameters_of(J, back, 2)
    np.testing.assert_allclose(back[2:], theta[2:], rtol=0, atol=1e-15)
    assert back[0] == back[1] == 7.0  # nothing before the body is touched


def test_the_eigenvalues_against_numpy_and_the_decomposition_rebuilt():
    rng = np.random.default_rng(11)
    for k in range(30):
        A = rng.normal(size=(4, 4))
        A = A + A.T
        if k == 0:
            A = np.diag([3.0, -1.0, 2.0, 0.5])  # already diagonal
        if k == 1:
            A[0, 1] = A[1, 0] = 0.0  # a zero off the diagonal
        w, V = np.empty(4), np.empty((4, 4))
        before = A.copy()
        pi.symmetric_eigen(A, w, V)
        np.testing.assert_array_equal(A, before)
        np.testing.assert_allclose(np.sort(w), np.linalg.eigvalsh(A), rtol=0, atol=1e-12 * np.abs(A).max())
        np.testing.assert_allclose(V @ np.diag(w) @ V.T, A, rtol=0, atol=1e-12 * np.abs(A).max())
        np.testing.assert_allclose(V.T @ V, np.eye(4), rtol=0, atol=1e-12)
    lo, total = pi.smallest_eigenvalue(np.diag([3.0, -1.0, 2.0, 0.5]))
    assert (lo, total) == (-1.0, 6.5)
    lo, total = pi.smallest_eigenvalue(np.diag([-0.5, -1.0, 2.0, 0.5]))
    assert (lo, total) == (-1.0, 4.0)


def test_off_diagonals_of_exactly_one_and_zeros_beside_equal_diagonals():
    """Every nonzero off-diagonal entry is rotated away, 1.0 as any other; a zero one is left alone even where the
    two diagonal entries are equal (its rotation angle would be 0/0)."""
    A = np.array([[2.0, 1.0, 0.0, 0.0], [1.0, 2.0, 0.0, 0.0], [0.0, 0.0, 2.0, 0.0], [0.0, 0.0, 0.0, 2.0]])
    w, V = np.empty(4), np.empty((4, 4))
    pi.symmetric_eigen(A, w, V)
    np.testing.assert_allclose(np.sort(w), [1.0, 2.0, 2.0, 3.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(V @ np.diag(w) @ V.T, A, rtol=0, atol=1e-15)


class _CountingMath:
    """math with its sqrt counted: the Jacobi iteration takes two square roots per rotation."""

    def __init__(self):
        self.calls = 0

    def __getattr__(self, name):
        return getattr(math, name)

    def sqrt(self, x):
        self.calls += 1
        return math.sqrt(x)


def test_the_jacobi_iteration_stops_once_converged(monkeypatch):
    """The decomposition runs in the compiled callback at every stage of every step: it stops when the off-diagonal
    is negligible (≤ 1e-36 of the diagonal's square sum), not after its 60 sweeps. On these 50 matrices it takes at
    most 30 rotations (6 a sweep, quadratic convergence); run on to exact zeros it would take some 40."""
    counting = _CountingMath()
    monkeypatch.setattr(pi, "math", counting)
    rng = np.random.default_rng(11)
    most = 0
    for _ in range(50):
        A = rng.normal(size=(4, 4))
        A = A + A.T
        counting.calls = 0
        pi.symmetric_eigen(A, np.empty(4), np.empty((4, 4)))
        most = max(most, counting.calls // 2)
    assert most <= 30
    counting.calls = 0
    pi.symmetric_eigen(np.diag([1.0, 2.0, 3.0, 4.0]), np.empty(4), np.empty((4, 4)))
    assert counting.calls == 0  # already diagonal: no rotation


def test_the_psd_part_clips_eigenvalues_at_zero():
    out = np.empty((4, 4))
    pi.psd_part(np.diag([3.0, -1.0, 2.0, -0.5]), out)
    np.testing.assert_allclose(out, np.diag([3.0, 0.0, 2.0, 0.0]), rtol=0, atol=1e-15)
    rng = np.random.default_rng(12)
    for _ in range(10):
        A = rng.normal(size=(4, 4))
        A = A + A.T
        lam, U = np.linalg.eigh(A)
        expected = U @ np.diag(np.maximum(lam, 0.0)) @ U.T
        pi.psd_part(A, out)
        np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12 * np.abs(A).max())


def test_the_gradient_against_central_finite_differences():
    """⟨G, E⟩ = d/dt f(X + tE) for every symmetric direction E (f written here, not the module's)."""
    rng = np.random.default_rng(13)
    for _ in range(5):
        gamma = np.exp(rng.normal(size=10))
        target = np.concatenate(([0.0], rng.normal(size=10)))
        X = rng.normal(size=(4, 4))
        X = X + X.T
        G = np.empty((4, 4))
        pi.objective_gradient(X, target, 1, gamma, G, np.empty(11))
        np.testing.assert_array_equal(G, G.T)
        h = 1e-6
        for i in range(4):
            for j in range(i, 4):
                E = np.zeros((4, 4))
                E[i, j] = E[j, i] = 1.0
                fd = (_objective(X + h * E, target[1:], gamma) - _objective(X - h * E, target[1:], gamma)) / (2 * h)
                assert np.sum(G * E) == pytest.approx(fd, rel=1e-6, abs=1e-8), (i, j)


def test_step_and_momentum_from_the_hessian_derived_by_hand():
    """Equal weights γ: in an orthonormal basis of symmetric X the Hessian is γ on m, γ/2 on each of the six
    off-diagonal directions (h and the products of inertia), and γ·[[2,1,1],[1,2,1],[1,1,2]] on the diagonal of Σ
    (eigenvalues 4γ, γ, γ): L = 4γ, κ = 8, β = (√8 − 1)/(√8 + 1)."""
    record = pi.body_record((3,), np.concatenate(([9.0] * 3, np.full(10, 0.25))))
    assert record[0] == 1.0 and record[1] == 3.0
    assert record[2] == pytest.approx(1.0, rel=1e-12)
    assert record[3] == pytest.approx((math.sqrt(8) - 1) / (math.sqrt(8) + 1), rel=1e-12)
    np.testing.assert_array_equal(record[4:], np.full(10, 0.25))
    assert record.shape == (1 + pi.BODY_FIELDS,)
    two = pi.body_record((0, 10), np.concatenate((np.full(10, 1.0), np.full(10, 2.0))))
    assert two[0] == 2.0 and two[1 + pi.BODY_FIELDS] == 10.0 and two[2 + pi.BODY_FIELDS] == pytest.approx(8.0)


@pytest.mark.parametrize("bad", [np.full(9, 0.2), np.array([0.2] * 9 + [0.0]), np.array([0.2] * 9 + [-1.0]),
                                 np.array([0.2] * 9 + [np.inf]), np.array([0.2] * 9 + [np.nan])])
def test_the_record_refuses_gains_that_are_not_ten_finite_and_positive(bad):
    with pytest.raises(ValueError, match="the body at parameter 0 needs ten finite adaptation gains > 0, got"):
        pi.body_record((0,), bad)


def test_the_tolerance_is_met_exactly_at_its_edge():
    assert pi.is_physical(-1e-12, 1.0) and not pi.is_physical(-1.0000001e-12, 1.0)
    assert pi.is_physical(0.0, 0.0) and pi.is_physical(-2e-12, 2.0) and not pi.is_physical(-2e-12, 1.0)
    np.testing.assert_array_equal(pi.is_physical(np.array([-1e-12, -3e-12]), np.array([1.0, 1.0])), [True, False])


def _solve(target, gamma):
    """The Γ-metric projection by scipy's generic solver: min over L (4×4 lower triangular) of f(π(L Lᵀ)), from a
    few starts; X = L Lᵀ is PSD by construction. Returns (objective, π)."""
    rows, cols = np.tril_indices(4)
    J = np.empty((4, 4))
    pi.pseudo_inertia(target, 0, J)
    lam, U = np.linalg.eigh(J)

    def f(v):
        L = np.zeros((4, 4))
        L[rows, cols] = v
        return _objective(L @ L.T, target, gamma)

    best = None
    starts = [np.linalg.cholesky(U @ np.diag(np.maximum(lam, 0.0) + 1e-3) @ U.T), np.eye(4)]
    for L0 in starts:
        res = minimize(f, L0[rows, cols], method="BFGS", options={"gtol": 1e-12, "maxiter": 20000})
        if best is None or res.fun < best.fun:
            best = res
    assert best is not None
    L = np.zeros((4, 4))
    L[rows, cols] = best.x
    return best.fun, _params_of_X(L @ L.T)


@pytest.mark.parametrize("seed", [21, 22, 23])
def test_the_projection_is_the_optimum_a_generic_solver_finds(seed):
    rng = np.random.default_rng(seed)
    gamma = np.exp(rng.normal(0.0, 0.7, 10))
    target = _theta(1.0, (0.1, -0.2, 0.05), [[0.02, 0.0, 0.0], [0.0, 0.03, 0.0], [0.0, 0.0, 0.08]])
    target = target + rng.normal(0.0, 0.05, 10)  # Izz > Ixx + Iyy and more: no body
    J = np.empty((4, 4))
    pi.pseudo_inertia(target, 0, J)
    assert np.linalg.eigvalsh(J)[0] < -1e-3
    record = pi.body_record((0,), gamma)
    theta = target.copy()
    assert pi.project_body(theta, 0, record[2], record[3], record[4:14])
    ours = 0.5 * float(np.sum(gamma * (theta - target) ** 2))
    theirs, pi_theirs = _solve(target, gamma)
    assert ours <= theirs * (1 + 1e-6) + 1e-14  # no worse than the generic solver
    assert ours >= theirs * (1 - 1e-4)  # and the same optimum (the solver stops a little short)
    np.testing.assert_allclose(theta, pi_theirs, rtol=0, atol=2e-3 * np.abs(target).max())
    pi.pseudo_inertia(theta, 0, J)
    lam = np.linalg.eigvalsh(J)
    assert lam[0] >= -pi.PSD_TOLERANCE * np.sum(np.abs(lam))


def test_the_projection_s_kkt_conditions_with_a_finite_difference_gradient():
    """At the optimum X* ⪰ 0 the gradient G (by central differences of f written here) is PSD and ⟨G, X*⟩ = 0."""
    rng = np.random.default_rng(31)
    for _ in range(6):
        gamma = np.exp(rng.normal(0.0, 1.0, 10))
        target = rng.normal(0.0, 1.0, 10)
        theta = target.copy()
        record = pi.body_record((0,), gamma)
        if not pi.project_body(theta, 0, record[2], record[3], record[4:14]):
            continue
        _assert_kkt(theta, target, gamma, 1e-6)


def test_every_body_of_a_record_is_projected_and_nothing_else():
    rng = np.random.default_rng(41)
    bad = rng.normal(0.0, 1.0, 10)
    bad[0] = -1.0  # a negative mass: no body
    body = _theta(2.0, (1.0, 2.0, 3.0), [[26.0, -4.0, -6.0], [-4.0, 20.0, -12.0], [-6.0, -12.0, 10.0]])
    theta = np.concatenate(([5.0], bad, [6.0], bad, body))
    gamma = np.full(theta.size, 0.3)
    record = pi.body_record((1, 12, 22), gamma)
    box = np.concatenate((np.zeros(theta.size), record))
    pi.project_bodies(theta, box, theta.size)
    assert theta[0] == 5.0 and theta[11] == 6.0
    np.testing.assert_array_equal(theta[22:], body)
    np.testing.assert_array_equal(theta[1:11], theta[12:22])  # the same input, the same projection
    lam = pi.eigenvalues(theta, (1, 12))
    assert lam.shape == (2, 4) and np.all(lam[:, 0] >= -1e-12 * np.abs(lam).sum(axis=1))
    assert not np.allclose(theta[1:11], bad)
    rows = pi.eigenvalues(np.stack([theta, theta, theta]), (1, 12, 22))
    assert rows.shape == (3, 3, 4)
    np.testing.assert_allclose(rows[2, 2], [0.0, 0.0, 0.0, 30.0], atol=1e-12)


def test_a_negative_mass_point_is_projected_to_no_mass():
    """π̂ = (−1, 0, …, 0): J = diag(0, 0, 0, −1); the nearest PSD J is 0, so every parameter ends at 0 (by hand: the
    other entries are already 0 and only m must move, to 0)."""
    theta = np.zeros(10)
    theta[0] = -1.0
    record = pi.body_record((0,), np.full(10, 1.0))
    assert pi.project_body(theta, 0, record[2], record[3], record[4:14])
    np.testing.assert_allclose(theta, np.zeros(10), atol=1e-14)


def _fd_gradient(X, target, gamma, h=1e-6):
    G = np.zeros((4, 4))
    for i in range(4):
        for j in range(i, 4):
            E = np.zeros((4, 4))
            E[i, j] = E[j, i] = 1.0
            d = (_objective(X + h * E, target, gamma) - _objective(X - h * E, target, gamma)) / (2 * h)
            G[i, j] = G[j, i] = d if i == j else d / 2
    return G

def _assert_kkt(theta, target, gamma, tol):
    """The optimum's conditions at the projected θ: closer to the target than the origin is, the finite-difference
    gradient G of f at X* = pseudo_inertia(θ) positive semidefinite and ⟨G, X*⟩ = 0, each to tol relative to ‖G‖."""
    X = np.empty((4, 4))
    pi.pseudo_inertia(theta, 0, X)
    G = _fd_gradient(X, target, gamma)
    scale = np.linalg.norm(G)
    assert scale > 1e-6 and np.sum(gamma * (theta - target) ** 2) <= np.sum(gamma * target**2)
    assert np.linalg.eigvalsh(G)[0] >= -tol * scale
    assert abs(np.sum(G * X)) <= tol * scale * np.linalg.norm(X)


def test_sixty_iterations_reach_the_optimum_with_equal_weights(monkeypatch):
    """The module's docstring: with equal γ the Hessian's condition number is 8 and about 60 accelerated steps reach
    1e-14; the KKT residuals (finite-difference gradient) after 60 are at rounding's level (plain gradient steps,
    without the momentum, are still some 1e-6 off)."""
    monkeypatch.setattr(pi, "MAX_ITERATIONS", 60)
    rng = np.random.default_rng(51)
    gamma = np.full(10, 0.2)
    record = pi.body_record((0,), gamma)
    moved = 0
    for _ in range(20):
        target = rng.normal(0.0, 1.0, 10)
        theta = target.copy()
        if not pi.project_body(theta, 0, record[2], record[3], record[4:14]):
            continue
        moved += 1
        _assert_kkt(theta, target, gamma, 1e-8)
    assert moved >= 10


def test_the_accelerated_gradient_stops_at_its_tolerance(monkeypatch):
    """The projection runs in the compiled callback at every stage: it stops once a step moves X by less than
    STEP_TOLERANCE of its size (some 60 to 75 iterations with equal weights here), not after MAX_ITERATIONS (400)."""
    calls = []
    gradient = pi.objective_gradient

    def counting(*args):
        calls.append(1)
        return gradient(*args)

    monkeypatch.setattr(pi, "objective_gradient", counting)
    rng = np.random.default_rng(61)
    record = pi.body_record((0,), np.full(10, 0.2))
    most = 0
    for _ in range(20):
        theta = rng.normal(0.0, 1.0, 10)
        calls.clear()
        assert pi.project_body(theta, 0, record[2], record[3], record[4:14])
        most = max(most, len(calls))
    assert 0 < most <= 100


def _hessian_eigenvalues_by_differences(gamma):
    """The objective's Hessian in an orthonormal basis of symmetric 4×4 matrices, by central second differences of
    f written here (target 0), and its eigenvalues."""
    basis = []
    for i in range(4):
        for j in range(i, 4):
            E = np.zeros((4, 4))
            E[i, j] = E[j, i] = 1.0 if i == j else 1.0 / math.sqrt(2.0)
            basis.append(E)
    zero = np.zeros(10)
    H = np.empty((10, 10))
    h = 1e-3
    for a, Ea in enumerate(basis):
        for b, Eb in enumerate(basis):
            H[a, b] = (_objective(h * (Ea + Eb), zero, gamma) - _objective(h * (Ea - Eb), zero, gamma)
                       - _objective(h * (Eb - Ea), zero, gamma) + _objective(-h * (Ea + Eb), zero, gamma)) / (4 * h * h)
    return np.linalg.eigvalsh(H)


def test_step_and_momentum_with_unequal_weights_from_a_hessian_by_differences():
    gamma = np.array([0.3, 1.0, 2.0, 0.5, 0.1, 0.7, 0.2, 1.5, 0.4, 0.9])
    lam = _hessian_eigenvalues_by_differences(gamma)
    kappa = lam[-1] / lam[0]
    record = pi.body_record((0,), gamma)
    assert record[2] == pytest.approx(lam[-1], rel=1e-6)
    assert record[3] == pytest.approx((math.sqrt(kappa) - 1) / (math.sqrt(kappa) + 1), rel=1e-6)


def test_every_body_of_a_record_gets_its_own_step_momentum_and_weights(monkeypatch):
    """Two bodies with different weights, projected through the record in 60 iterations: each meets its own KKT
    conditions (finite-difference gradient in its own metric), so each read its own L, β and γ."""
    monkeypatch.setattr(pi, "MAX_ITERATIONS", 60)
    rng = np.random.default_rng(71)
    g1, g2 = np.full(10, 3.0), np.full(10, 0.2)  # L = 12 at index 1, L = 0.8 at index 13: neither is its start
    t1, t2 = rng.normal(0.0, 1.0, 10), rng.normal(0.0, 1.0, 10)
    t1[0] = t2[0] = -0.5  # negative masses: both move
    theta = np.concatenate(([7.0], t1, [8.0, 9.0], t2))
    record = pi.body_record((1, 13), np.concatenate(([1.0], g1, [1.0, 1.0], g2)))
    pi.project_bodies(theta, np.concatenate((np.zeros(theta.size), record)), theta.size)
    assert (theta[0], theta[11], theta[12]) == (7.0, 8.0, 9.0)
    for start, target, gamma in ((1, t1, g1), (13, t2, g2)):
        moved = theta[start:start + 10] - target
        assert np.sum(gamma * moved**2) <= np.sum(gamma * target**2)  # no farther than the body 0 (J = 0 ⪰ 0)
        X = np.empty((4, 4))
        pi.pseudo_inertia(theta, start, X)
        G = _fd_gradient(X, target, gamma)
        scale = np.linalg.norm(G)
        assert scale > 1e-3  # the target is no body: the gradient at the optimum is not 0
        assert np.linalg.eigvalsh(G)[0] >= -1e-8 * scale
        assert abs(np.sum(G * X)) <= 1e-8 * scale * np.linalg.norm(X)
