"""Plants: the only code that touches MjModel/MjData (plus the analytic twin).

Every plant offers the same small interface to the loop:
  form        ModelForm: the structure the law assumes
  dt          physics step [s]
  time        current simulation time [s]
  ctrl_range  (lo, hi) actuator limits in control units, or None
  observe()   (n,) true state [y, y', ...]
  true_theta() (n_theta,) true parameters, ordered as form.names
  controlled_by(policy)  context manager: policy(t, x) -> u runs at every
                         evaluation of the dynamics (MuJoCo's control callback)
  step()      advance one physics step
"""
