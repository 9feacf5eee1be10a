"""The model's rigid-body dynamics about the pivot, as a value (``Dynamics``): the configuration
(inertia J about the pivot, m rho, gravity, the disturbance model), J^-1 and the adaptive estimate
Delta_bar in force. The control step's feed-forward, the brake's inputs and the delay prediction
evaluate it; none needs the controller for it. Notation as ``geoctl_ros.core.law.control``'s.

Its moment and acceleration are one formula by components (``_moments``: floats for one run,
arrays for a batch; ``core.geometry.elementwise``), the products in index order as every
product here, so a run gives the same bits alone and in a batch.
"""
from typing import List, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from geoctl_ros.core.geometry.elementwise import (
    Value,
    joined,
    matrix_parts,
    one_run,
    vector_parts,
)
from geoctl_ros.core.geometry.so3 import FloatArray
from geoctl_ros.core.law.controller_config import ControllerConfig
from geoctl_ros.core.law.mechanics import (
    Parts,
    Rows,
    body_gravity_parts,
    cog_regressor,
    cog_regressor_parts,
    cross_parts,
    gravity_moment,
)

_EYE3 = np.eye(3)
_EYE3.flags.writeable = False
_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


class ModelParts(NamedTuple):
    """The model's constants as floats, made once per configuration (a batch shares them):
    J and J^-1 by rows, m rho, gravity (world frame), and whether the estimate has the
    constant+cog regressor (else W = I).
    """

    J: List[List[float]]
    J_inv: List[List[float]]
    m_rho: List[float]
    gravity: List[float]
    cog: bool

    @classmethod
    def of(cls, config: ControllerConfig, J_inv: FloatArray) -> 'ModelParts':
        """The parts of a configuration (its J, m rho and gravity one run's: 3x3 and 3)."""
        return cls(config.J.reshape(3, 3).tolist(), J_inv.reshape(3, 3).tolist(),
                   config.m_rho.reshape(3).tolist(), config.gravity.reshape(3).tolist(),
                   config.disturbance_model != 'constant')


def _moments(p: ModelParts, R: Rows, Omega: Parts,
             d: Parts) -> Tuple[List[Value], List[Value]]:
    """(M_g, the model's moment besides the rotors') by components: M_g(R) + W Delta_bar -
    Omega x J Omega, W = [I, -hat(R^T g)] for the constant+cog estimate (its products in index
    order, the identity's too), else I.
    """
    g_b = body_gravity_parts(R, p.gravity)
    M_g = cross_parts(p.m_rho, g_b)
    if p.cog:
        Y = cog_regressor_parts(g_b)
        Wd: Sequence[Value] = [
            e_i[0] * d[0] + e_i[1] * d[1] + e_i[2] * d[2] + Y_i[0] * d[3] + Y_i[1] * d[4]
            + Y_i[2] * d[5] for e_i, Y_i in zip(_IDENTITY, Y)]
    else:
        Wd = d
    J = p.J
    JO = [J[i][0] * Omega[0] + J[i][1] * Omega[1] + J[i][2] * Omega[2] for i in range(3)]
    gyro = cross_parts(Omega, JO)
    return M_g, [(M_g[i] + Wd[i]) - gyro[i] for i in range(3)]


class Dynamics(NamedTuple):
    """The model's dynamics with an estimate (see the module)."""

    config: ControllerConfig
    J_inv: FloatArray
    delta_bar: FloatArray         # the estimate in force (the controller's own array)
    parts: ModelParts

    def regressor(self, R: FloatArray) -> Optional[FloatArray]:
        """W(R): 3 x n_params (a stack of them for a batch); None for the constant model, where
        W = I.
        """
        if not self.parts.cog:
            return None
        Y = cog_regressor(R, self.config.gravity)
        if Y.ndim == 2:                     # one run: no broadcast, the identity made once
            return np.concatenate((_EYE3, Y), axis=1)
        return np.concatenate((np.broadcast_to(_EYE3, Y.shape), Y), axis=-1)

    def gravity_moment(self, R: FloatArray) -> FloatArray:
        """The model's gravity moment at R (about the pivot, body frame)."""
        return gravity_moment(R, self.config.m_rho, self.config.gravity)

    def moments(self, R: FloatArray, Omega: FloatArray) -> Tuple[FloatArray, FloatArray]:
        """(M_g, f) at (R, Omega): the gravity moment and the model's whole moment besides the
        rotors', f = M_g(R) + W Delta_bar - Omega x J Omega (about the pivot, body frame).
        """
        one = one_run(R)
        M_g, f = _moments(self.parts, matrix_parts(R, one), vector_parts(Omega, one),
                          vector_parts(self.delta_bar, one))
        lead = R.shape[:-2]
        return joined(M_g, lead, one), joined(f, lead, one)

    def moment(self, R: FloatArray, Omega: FloatArray) -> FloatArray:
        """f: the model's moment besides the rotors' at (R, Omega) (``moments``)."""
        return self.moments(R, Omega)[1]

    def acceleration(self, R: FloatArray, Omega: FloatArray, moment: FloatArray) -> FloatArray:
        """The model's angular acceleration at (R, Omega) under the rotors' moment (about the
        pivot): J^-1 (moment + f).
        """
        one = one_run(R)
        return joined(self.acceleration_parts(
            matrix_parts(R, one), vector_parts(Omega, one), vector_parts(moment, one),
            vector_parts(self.delta_bar, one)), R.shape[:-2], one)

    def acceleration_parts(self, R: Rows, Omega: Parts, moment: Parts,
                           delta_bar: Parts) -> List[Value]:
        """``acceleration`` by components (with the estimate's)."""
        _, f = _moments(self.parts, R, Omega, delta_bar)
        return self.J_inv_times([moment[i] + f[i] for i in range(3)])

    def J_inv_times(self, v: Parts) -> List[Value]:
        """J^-1 v by components."""
        Ji = self.parts.J_inv
        return [Ji[i][0] * v[0] + Ji[i][1] * v[1] + Ji[i][2] * v[2] for i in range(3)]
