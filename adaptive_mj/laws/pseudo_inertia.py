"""The physically consistent projection of rigid-body parameter estimates (law.projection = "consistent").

A body's ten standard parameters π = [m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] (inertia about the body
frame's origin, adaptive_mj.plants.regressor_kernel.BODY_PARAM_NAMES) belong to some distribution of mass exactly
when its pseudo-inertia

    J(π) = [[Σ, h], [hᵀ, m]],   Σ = ½ tr(I)·1 − I  (the second moment of the mass about the origin),  h = m c,

is positive semidefinite (Wensing, Kim & Slotine, "Linear matrix inequalities for physically consistent inertial
parameter identification", RA-L 2017). The set {π : J(π) ⪰ 0} is a convex cone, and it is a strict subset of the
box the older preset law.projection = "nonnegative" keeps (m ≥ 0 and each principal moment ≥ 0): the triangle
inequalities Ixx ≤ Iyy + Izz and |c| bounded by the spread of the mass follow from J ⪰ 0, not from the box.

The projection is onto that set in the adaptation's own metric, ‖π − π̂‖²_Γ = Σ γ_i (π_i − π̂_i)² (Γ the law's
stiffnesses: θ̂' = Yᵀ s / γ), because that is the metric of the parameter part ½ θ̃ᵀ Γ θ̃ of Slotine–Li's
Lyapunov function: with θ in the set, the Γ-metric projection P satisfies ‖P(θ̂) − θ‖_Γ ≤ ‖θ̂ − θ‖_Γ (projection
onto a closed convex set is non-expansive), so projecting an estimate never raises V (docs/THEORY.md,
"The physically consistent projection"). The problem per body,

    min_X ½ ‖π(X) − π̂‖²_Γ   over symmetric X ⪰ 0   (X = J(π), π(X) its inverse: a linear bijection),

is solved by accelerated projected gradient in X with the Frobenius projection onto the PSD cone (eigenvalues
clipped at 0) as its prox: the iterate returned is always that projection's output, so the result is PSD to
rounding whatever the iteration count. The step 1/L and the momentum come from the extreme eigenvalues of the
objective's Hessian in X (body_record, computed once); with equal γ over a body its condition number is 8, and
about 60 iterations reach 1e-14.

Plain loops over arrays (numba compiles them into the callbacks with the stage functions). The record a law
carries (body_record, appended to its projection box by common.Modification) is, per body: the index of its m in
θ̂, L, the momentum β and the ten weights γ_i; as a flat array [n_bodies, (start, L, β, γ_0 … γ_9) × n_bodies].
"""
from __future__ import annotations

import math

import numpy as np

#: entries of the record per body: start, L, β, then the ten weights
BODY_FIELDS = 13
#: a pseudo-inertia counts as PSD while its smallest eigenvalue is ≥ −PSD_TOLERANCE × Σ|λ| (the rounding of
#: J(π(X)) for a PSD X is about 1e-16 of it)
PSD_TOLERANCE = 1e-12
#: the accelerated gradient's stopping rule: ‖X_{k+1} − X_k‖_F ≤ STEP_TOLERANCE × ‖X_{k+1}‖_F, or MAX_ITERATIONS
STEP_TOLERANCE = 1e-14
MAX_ITERATIONS = 400


def pseudo_inertia(theta, start, J):
    """J (4, 4) = the pseudo-inertia of the body whose parameters are theta[start:start + 10] (module docstring).
    [kg m², kg m, kg]"""
    m, hx, hy, hz = theta[start], theta[start + 1], theta[start + 2], theta[start + 3]
    ixx, ixy, iyy = theta[start + 4], theta[start + 5], theta[start + 6]
    ixz, iyz, izz = theta[start + 7], theta[start + 8], theta[start + 9]
    half = 0.5 * (ixx + iyy + izz)
    J[0, 0], J[1, 1], J[2, 2], J[3, 3] = half - ixx, half - iyy, half - izz, m
    J[0, 1] = J[1, 0] = -ixy
    J[0, 2] = J[2, 0] = -ixz
    J[1, 2] = J[2, 1] = -iyz
    J[0, 3] = J[3, 0] = hx
    J[1, 3] = J[3, 1] = hy
    J[2, 3] = J[3, 2] = hz


def parameters_of(J, theta, start):
    """theta[start:start + 10] = π(J), the inverse of pseudo_inertia: I = tr(Σ)·1 − Σ, h and m read off."""
    tr = J[0, 0] + J[1, 1] + J[2, 2]
    theta[start] = J[3, 3]
    theta[start + 1], theta[start + 2], theta[start + 3] = J[0, 3], J[1, 3], J[2, 3]
    theta[start + 4], theta[start + 6], theta[start + 9] = tr - J[0, 0], tr - J[1, 1], tr - J[2, 2]
    theta[start + 5], theta[start + 7], theta[start + 8] = -J[0, 1], -J[0, 2], -J[1, 2]


def symmetric_eigen(A, w, V):
    """Eigen-decomposition of a symmetric (4, 4) A by cyclic Jacobi rotations: w (4,) the eigenvalues, V (4, 4)
    the eigenvectors as columns (A = V diag(w) Vᵀ); A is left unchanged. Accurate to rounding for any symmetric
    A (no LAPACK: the same operations in Python and compiled)."""
    n = 4
    B = np.empty((4, 4))
    for i in range(n):
        for j in range(n):
            B[i, j] = A[i, j]
            V[i, j] = 1.0 if i == j else 0.0
    for _sweep in range(60):
        off = 0.0
        scale = 0.0
        for i in range(n):
            scale += B[i, i] * B[i, i]
            for j in range(i + 1, n):
                off += B[i, j] * B[i, j]
        if off == 0.0 or off <= 1e-36 * scale:
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                if B[p, q] == 0.0:
                    continue
                theta = (B[q, q] - B[p, p]) / (2.0 * B[p, q])
                t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(n):  # B <- Rᵀ B R, R the rotation in the (p, q) plane
                    bkp, bkq = B[k, p], B[k, q]
                    B[k, p], B[k, q] = c * bkp - s * bkq, s * bkp + c * bkq
                for k in range(n):
                    bpk, bqk = B[p, k], B[q, k]
                    B[p, k], B[q, k] = c * bpk - s * bqk, s * bpk + c * bqk
                B[p, q] = B[q, p] = 0.0
                for k in range(n):
                    vkp, vkq = V[k, p], V[k, q]
                    V[k, p], V[k, q] = c * vkp - s * vkq, s * vkp + c * vkq
    for i in range(n):
        w[i] = B[i, i]


def smallest_eigenvalue(J):
    """(smallest eigenvalue of the symmetric (4, 4) J, Σ|λ|)."""
    w, V = np.empty(4), np.empty((4, 4))
    symmetric_eigen(J, w, V)
    lo, total = w[0], 0.0
    for i in range(4):
        lo = min(lo, w[i])
        total += abs(w[i])
    return lo, total


def psd_part(A, out):
    """out (4, 4) = the Frobenius projection of the symmetric A onto the PSD cone: V diag(max(λ, 0)) Vᵀ."""
    w, V = np.empty(4), np.empty((4, 4))
    symmetric_eigen(A, w, V)
    for i in range(4):
        for j in range(i, 4):
            acc = 0.0
            for k in range(4):
                if w[k] > 0.0:
                    acc += V[i, k] * w[k] * V[j, k]
            out[i, j] = out[j, i] = acc


def objective_gradient(X, target, start, weights, G, work):
    """G (4, 4) = the gradient, in the Frobenius inner product on symmetric matrices, of ½ Σ γ_i (π_i(X) − π̂_i)²
    (π̂ = target[start:start + 10], γ = weights (10,)); work (≥ start + 10,) scratch for π(X)."""
    parameters_of(X, work, start)
    r = np.empty(10)
    for i in range(10):
        r[i] = weights[i] * (work[start + i] - target[start + i])
    # dm = dX33; dh = dX_i3 (= dX_3i); dI_xx = dX11 + dX22 (Ixx = tr Σ − Σxx), …; dI_xy = −dX01, …
    G[3, 3] = r[0]
    G[0, 3] = G[3, 0] = 0.5 * r[1]
    G[1, 3] = G[3, 1] = 0.5 * r[2]
    G[2, 3] = G[3, 2] = 0.5 * r[3]
    G[0, 0] = r[6] + r[9]
    G[1, 1] = r[4] + r[9]
    G[2, 2] = r[4] + r[6]
    G[0, 1] = G[1, 0] = -0.5 * r[5]
    G[0, 2] = G[2, 0] = -0.5 * r[7]
    G[1, 2] = G[2, 1] = -0.5 * r[8]


def project_body(theta, start, lipschitz, momentum, weights):
    """θ̂[start:start + 10] replaced, in place, by its Γ-metric projection onto {π : J(π) ⪰ 0} when J(θ̂) is not
    PSD (within PSD_TOLERANCE); left unchanged (bit for bit) when it is. Returns whether it moved."""
    J = np.empty((4, 4))
    pseudo_inertia(theta, start, J)
    lo, total = smallest_eigenvalue(J)
    if is_physical(lo, total):
        return False
    target = np.empty(start + 10)
    work = np.empty(start + 10)
    for i in range(10):
        target[start + i] = theta[start + i]
    X, X_prev, Y, G, step = np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4))
    psd_part(J, X)
    for i in range(4):
        for j in range(4):
            Y[i, j] = X[i, j]
    for _ in range(MAX_ITERATIONS):
        for i in range(4):
            for j in range(4):
                X_prev[i, j] = X[i, j]
        objective_gradient(Y, target, start, weights, G, work)
        for i in range(4):
            for j in range(4):
                step[i, j] = Y[i, j] - G[i, j] / lipschitz
        psd_part(step, X)
        moved, size = 0.0, 0.0
        for i in range(4):
            for j in range(4):
                d = X[i, j] - X_prev[i, j]
                moved += d * d
                size += X[i, j] * X[i, j]
                Y[i, j] = X[i, j] + momentum * d
        if moved <= STEP_TOLERANCE * STEP_TOLERANCE * size:
            break
    parameters_of(X, theta, start)
    return True


def project_bodies(theta, record, offset):
    """Every body of the record (record[offset:], module docstring) projected in place (project_body)."""
    count = int(record[offset])
    for b in range(count):
        base = offset + 1 + b * BODY_FIELDS
        project_body(theta, int(record[base]), record[base + 1], record[base + 2],
                     record[base + 3: base + BODY_FIELDS])


def body_record(starts, gamma) -> np.ndarray:
    """The flat record (1 + 13 n_bodies,) of the bodies whose parameters start at `starts` (indices of each m in
    θ̂), with the weights γ (n_theta,) of the law: per body its start, L = λ_max and β = (√κ − 1)/(√κ + 1) of the
    objective's Hessian in X (κ = λ_max/λ_min; the accelerated gradient's step and momentum)."""
    gamma = np.asarray(gamma, dtype=float)
    out = [float(len(starts))]
    for start in starts:
        w = gamma[start:start + 10]
        if w.shape != (10,) or not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise ValueError(f"the body at parameter {start} needs ten finite adaptation gains > 0, got {w}")
        hess = _hessian(w)
        eig = np.linalg.eigvalsh(hess)
        kappa = eig[-1] / eig[0]
        out += [float(start), float(eig[-1]), float((math.sqrt(kappa) - 1.0) / (math.sqrt(kappa) + 1.0)), *w]
    return np.array(out)


def _hessian(weights: np.ndarray) -> np.ndarray:
    """(10, 10) the objective's Hessian in an orthonormal basis of the symmetric 4×4 matrices (Frobenius): the
    gradient map (linear in X for the target 0) applied to each basis matrix."""
    basis = []
    for i in range(4):
        for j in range(i, 4):
            E = np.zeros((4, 4))
            if i == j:
                E[i, i] = 1.0
            else:
                E[i, j] = E[j, i] = 1.0 / math.sqrt(2.0)
            basis.append(E)
    H = np.zeros((10, 10))
    G, work, zero = np.zeros((4, 4)), np.zeros(10), np.zeros(10)
    for b, E in enumerate(basis):
        objective_gradient(E, zero, 0, weights, G, work)
        for a, F in enumerate(basis):
            H[a, b] = float(np.sum(F * G))
    return 0.5 * (H + H.T)


def is_physical(lowest, total):
    """Whether a pseudo-inertia whose smallest eigenvalue is `lowest` and whose Σ|λ| is `total` counts as PSD
    (lowest ≥ −PSD_TOLERANCE · total): scalars in the compiled projection, arrays (one per row) in numpy."""
    return lowest >= -PSD_TOLERANCE * total


def eigenvalues(theta, starts) -> np.ndarray:
    """Each body's pseudo-inertia eigenvalues, ascending (numpy: the scenario check, the report and the tests):
    theta (n_theta,) gives (len(starts), 4); rows of θ̂ (N, n_theta) give (N, len(starts), 4)."""
    th = np.asarray(theta, dtype=float)
    columns = th.reshape(-1, th.shape[-1]).T  # (n_theta, N): pseudo_inertia fills J[i, j] (N,) for every row at once
    J = np.empty((len(starts), 4, 4, columns.shape[1]))
    for k, start in enumerate(starts):
        pseudo_inertia(columns, start, J[k])
    out = np.linalg.eigvalsh(np.moveaxis(J, -1, 0))  # (N, len(starts), 4)
    return out[0] if th.ndim == 1 else out

