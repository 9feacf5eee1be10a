"""The model's rigid-body dynamics about the pivot, as a value (``Dynamics``): the configuration
(inertia J about the pivot, m rho, gravity, the disturbance model), J^-1 and the adaptive estimate
Delta_bar in force. The control step's feed-forward and the delay prediction both evaluate it;
neither needs the controller for it. Notation as ``geoctl_ros.core.law.control``'s.
"""
from typing import Literal, NamedTuple, Optional, Union

import numpy as np

from geoctl_ros.core.geometry.so3 import FloatArray, cross, matvec
from geoctl_ros.core.law.controller_config import ControllerConfig
from geoctl_ros.core.law.mechanics import cog_regressor, gravity_moment

_EYE3 = np.eye(3)
_EYE3.flags.writeable = False


class Dynamics(NamedTuple):
    """The model's dynamics with an estimate (see the module)."""

    config: ControllerConfig
    J_inv: FloatArray
    delta_bar: FloatArray         # the estimate in force (the controller's own array)

    def regressor(self, R: FloatArray) -> Optional[FloatArray]:
        """W(R): 3 x n_params (a stack of them for a batch); None for the constant model, where
        W = I.
        """
        if self.config.disturbance_model == 'constant':
            return None
        Y = cog_regressor(R, self.config.gravity)
        if Y.ndim == 2:                     # one run: no broadcast, the identity made once
            return np.concatenate((_EYE3, Y), axis=1)
        return np.concatenate((np.broadcast_to(_EYE3, Y.shape), Y), axis=-1)

    def gravity_moment(self, R: FloatArray) -> FloatArray:
        """The model's gravity moment at R (about the pivot, body frame)."""
        return gravity_moment(R, self.config.m_rho, self.config.gravity)

    def moment(self, R: FloatArray, Omega: FloatArray, M_g: Optional[FloatArray] = None,
               W: Union[Literal[False], Optional[FloatArray]] = False,
               delta_bar: Optional[FloatArray] = None) -> FloatArray:
        """The model's moment about the pivot besides the rotors': M_g(R) + W Delta_bar -
        Omega x J Omega (``delta_bar``: this estimate instead of the one in force). M_g, W: the
        gravity moment and regressor at R when the step has them (``StepTerms``; W False: not
        given, since None is the constant model's regressor).
        """
        if W is False:
            W = self.regressor(R)
        if M_g is None:
            M_g = self.gravity_moment(R)
        d = self.delta_bar if delta_bar is None else delta_bar
        return M_g + (d if W is None else matvec(W, d)) - cross(Omega,
                                                                matvec(self.config.J, Omega))

    def acceleration(self, R: FloatArray, Omega: FloatArray, moment: FloatArray,
                     delta_bar: Optional[FloatArray] = None, M_g: Optional[FloatArray] = None,
                     W: Union[Literal[False], Optional[FloatArray]] = False) -> FloatArray:
        """The model's angular acceleration at (R, Omega) under the rotors' moment (about the
        pivot): J^-1 (moment + ``moment``'s).
        """
        return matvec(self.J_inv, moment + self.moment(R, Omega, M_g, W, delta_bar))
