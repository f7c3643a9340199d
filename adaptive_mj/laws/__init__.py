"""The lecture's control laws, as plain code over arrays (no mujoco here).

Every law is called as ``law(t, x, ref, theta_hat) -> LawStep`` with
  t: time [s]; x: (n,) measured [y, y', ..., y^(n-1)];
  ref: (n+1,) [y_d, y_d', ..., y_d^(n)]; theta_hat: (n_theta,) estimates,
and returns the control, the estimate derivative and the sliding variable.
``law.lyapunov(s, theta_hat, theta)`` evaluates the lecture's V. The whole interface the loop
relies on, with its optional members, is the protocol ``laws.protocol.Law``.
"""
from adaptive_mj.laws.common import DeadZone, DeadZoneOn, LawStep, Modification
from adaptive_mj.laws.composite import CompositeSlidingLaw
from adaptive_mj.laws.first_order import FirstOrderAdaptiveLaw
from adaptive_mj.laws.protocol import Law
from adaptive_mj.laws.sliding import FixedNominalLaw, RobustSlidingLaw, SlidingAdaptiveLaw

__all__ = [
    "DeadZone",
    "DeadZoneOn",
    "LawStep",
    "Modification",
    "CompositeSlidingLaw",
    "FirstOrderAdaptiveLaw",
    "Law",
    "SlidingAdaptiveLaw",
    "FixedNominalLaw",
    "RobustSlidingLaw",
]
