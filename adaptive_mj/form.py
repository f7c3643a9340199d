"""The known structure of a plant, as the lecture writes it:

    d * y^(n) = f(x) + phi(x) . p + h(x) * u,     x = [y, y', ..., y^(n-1)]

d (the leading coefficient) and p are unknown; f, phi and h are known
functions of the state. The parameter vector of a law is
theta = [d, p_1, ..., p_m] with names ``(d_name, *p_names)``; when
``d_name`` is None the leading coefficient is known to be 1 (the lecture's
first-order form x' = f + phi p + u) and theta = p.

Pure numpy: no mujoco here, so laws can import it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


def plain_dot(a: np.ndarray, b: np.ndarray) -> float:
    """a · b for two (m,) vectors, summed from index 0 with one rounding per product and per sum: the compiled
    loops' order (adaptive_mj.plants.twin.twin_rate), so that both paths give the same bits on every machine.
    numpy's `a @ b` hands the sum to BLAS, whose kernel depends on the CPU (OpenBLAS fuses the multiply and add on
    AVX-512: one ulp apart from this in about a quarter of draws)."""
    acc = 0.0
    for j in range(len(a)):
        acc += float(a[j]) * float(b[j])
    return acc


def _zero(x: np.ndarray) -> float:
    return 0.0


def _one(x: np.ndarray) -> float:
    return 1.0


@dataclass(frozen=True)
class ModelForm:
    """d*y^(n) = f(x) + phi(x).p + h(x)*u.

    order: n >= 1.
    p_names: names of the entries of p, in the order phi returns them.
    phi: x (n,) -> (len(p_names),) regressor.
    f: x (n,) -> float, known drift (default 0).
    h: x (n,) -> float, known, non-zero input gain (default 1).
    d_name: name of the unknown leading coefficient, or None when d = 1 is known.
    """

    order: int
    p_names: tuple[str, ...]
    phi: Callable[[np.ndarray], np.ndarray]
    f: Callable[[np.ndarray], float] = _zero
    h: Callable[[np.ndarray], float] = _one
    d_name: str | None = "d"

    @property
    def names(self) -> tuple[str, ...]:
        """Names of theta, in order: (d_name, *p_names) or p_names."""
        return self.p_names if self.d_name is None else (self.d_name, *self.p_names)

    def split(self, theta: np.ndarray) -> tuple[float | np.ndarray, np.ndarray]:
        """theta (..., n_theta) -> (d, p): d is 1.0 when the form has no unknown d."""
        theta = np.asarray(theta, dtype=float)
        if self.d_name is None:
            return 1.0, theta
        return theta[..., 0], theta[..., 1:]

    def highest_derivative(self, x: np.ndarray, u: float, theta: np.ndarray, external: float = 0.0) -> float:
        """y^(n) from the true equation (plus an external force), for the analytic twin."""
        d, p = self.split(theta)
        return float((self.f(x) + plain_dot(self.phi(x), p) + self.h(x) * u + external) / d)
