"""The projection's invariant in the closed loop: with a box (Modification lower/upper),
every estimate the law is ever called with (each RK4 stage's, not only each step's,
which is all the log records) lies in [lower, upper] (adaptive_mj.sim.loop: the stage
estimates θ̂_k + h a_i k_{i-1} are clipped as well as θ̂_{k+1})."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_mj import run
from adaptive_mj.laws import Modification, SlidingAdaptiveLaw
from adaptive_mj.plants import heave, twin
from adaptive_mj.reference import Cosine
from adaptive_mj.sim.loop import TABLEAU


class RecordingLaw:
    """Wraps a law; records the estimate it is called with and the rate it returns, per call."""

    def __init__(self, inner):
        self.inner = inner
        self.theta_hats: list[np.ndarray] = []
        self.rates: list[np.ndarray] = []

    def __getattr__(self, name):  # order, names, bounds, lyapunov, ... of the wrapped law
        return getattr(self.inner, name)

    def __call__(self, t, x, ref, theta_hat):
        out = self.inner(t, x, ref, theta_hat)
        self.theta_hats.append(np.array(theta_hat, dtype=float))
        self.rates.append(np.array(out.theta_hat_dot, dtype=float))
        return out


PLANTS = {
    "mujoco": lambda: heave.load(),
    "twin": lambda: twin.TwinPlant(heave.heave_form(9.81), [37.0, 60.0, 1.0], dt=1e-3,
                                   integrator=twin.Integrator.RK4, x0=[0.0, 0.0]),
}


@pytest.mark.parametrize("plant", list(PLANTS))
def test_every_stage_estimate_lies_in_the_projection_box(plant):
    """A box tight around θ̂₀ (true θ = [37, 60, 1] far outside it) and fast adaptation: the
    estimates sit on the faces and leave them whenever s changes sign, by more within half a
    step than the box allows, so unclipped stage estimates would leave it."""
    plant = PLANTS[plant]()
    assert plant.stages == 4
    th0 = np.array([30.0, 50.0, 0.8])
    lower, upper = th0 - [0.5, 0.5, 0.05], th0 + [0.5, 0.5, 0.05]
    law = RecordingLaw(SlidingAdaptiveLaw(heave.heave_form(9.81), lam=5.0, k=200.0, gamma=[2.5e-5, 2e-5, 5e-3],
                                          modification=Modification(lower=lower, upper=upper)))
    traj = run(plant, law, Cosine(amplitude=0.5, omega=3.0), duration=1.0, theta_hat0=th0, native=False)
    assert traj.status == "ok" and not traj.meta["native"]
    seen, rates = np.array(law.theta_hats), np.array(law.rates)
    n = len(traj.t)
    assert seen.shape == (4 * n, 3)  # four stages per step, no other call
    np.testing.assert_array_equal(seen[::4], traj.theta_hat)  # stage 1 is the logged step estimate

    # the invariant: every estimate the law saw, at every stage, is in the box
    assert np.all(seen >= lower) and np.all(seen <= upper)
    # ... and it is held on the faces, not just never reached
    assert np.all(np.any(seen == lower, axis=0)) and np.all(np.any(seen == upper, axis=0))

    # the case is one where the stage clip matters: θ̂_k + h a_i k_{i-1} (from the step's
    # estimate and the previous stage's rate, as the loop forms it) leaves the box
    inc, h = TABLEAU[4][0], plant.dt
    unclipped = np.array([seen[4 * k] + h * inc[i] * rates[4 * k + i - 1] for k in range(n) for i in (1, 2, 3)])
    outside = np.any((unclipped < lower) | (unclipped > upper), axis=1)
    assert np.count_nonzero(outside) >= 5
