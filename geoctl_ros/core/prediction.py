"""Delay compensation: the attitude and rate at the control tick from measurements that are some
time old, by the controller's own model of the testbed (``DelayPredictor``).
"""
from geoctl_ros.core import so3
from geoctl_ros.core.mechanics import gravity_moment
from geoctl_ros.core.so3 import cross, matvec

PREDICT_SLOW_S = 0.25     # s, what delay compensation counts as the model's slow error


class DelayPredictor:
    """The prediction of one run or a batch, with its state: the slow part of the model's
    acceleration, low-passed over the ticks.
    """

    def __init__(self, controller):
        """controller: the AttitudeController whose model (inertia, gravity, estimate) it uses."""
        self.controller = controller
        self._acc_slow = 0.0

    def __call__(self, R, Omega, age_R, age_Omega, moment, dt):
        """Delay compensation: the attitude and rate at the control tick from measurements age_R
        and age_Omega seconds old (scalars, or one per run of a batch), given the moment the rotors
        produce (the last allocation's). Ages of 0 return the measurements unchanged.

        The angular acceleration is the model's, J^-1 (moment + M_g(R) + W Delta_bar - Omega x J
        Omega) (Delta_bar standing for the disturbance it estimates), less its own slow part
        (low-pass, time constant PREDICT_SLOW_S; dt is the time since the last call), held over the
        age: Omega <- Omega + age_Omega Omega', R <- R exp(hat(Omega + age_R Omega' / 2) age_R).
        The slow part is what the model gets wrong at rest: there the true acceleration is zero
        while the model's is J^-1 times the moment not yet learnt (k_R e_R of the steady error);
        predicting with it would soften the attitude loop (the demo's final error went from 5.5 to
        15 deg). The fast part, which the delay turns into lost damping, is kept. A measurement 10
        ms old on the testbed, with its 40 ms motor lag, otherwise costs the rate loop most of its
        phase margin (README, "Safety campaign").
        """
        c = self.controller
        cfg = c.config
        W = c.regressor(R)
        acc = matvec(c.J_inv, moment + gravity_moment(R, cfg.m_rho, cfg.gravity)
                     + (c.delta_bar if W is None else matvec(W, c.delta_bar))
                     - cross(Omega, matvec(cfg.J, Omega)))
        self._acc_slow = self._acc_slow + (acc - self._acc_slow) * (dt / (PREDICT_SLOW_S + dt))
        acc = acc - self._acc_slow
        acc_R = (acc.T * age_R).T
        Omega_now = Omega + (acc.T * age_Omega).T
        return R @ so3.exp(((Omega + 0.5 * acc_R).T * age_R).T), Omega_now
