"""The delay-robust law (the default): the paper's law made robust to delay (the safety envelope),
each cone's barrier widened by what the sensor travels towards it over the blind time, up to
``blind_guard_max_deg`` (docs/safety.md, "Delay"), and the approach brake. With fresh inputs on
time and the brake off it is the paper's.
"""
from typing import Optional, cast

from geoctl_ros.core.geometry.so3 import FloatArray
from geoctl_ros.core.law.brake import BrakeInputs, braked
from geoctl_ros.core.law.cones import ConeEval
from geoctl_ros.core.law.projection import Polytope
from geoctl_ros.core.law.step_types import ControlOutput, Law, LawModel, StepTerms


def approach_brake(out: ControlOutput, terms: StepTerms, R: FloatArray, Omega: FloatArray,
                   model: LawModel, brake: Optional[BrakeInputs]) -> ControlOutput:
    """The law's moment kept by the approach brake (``core.law.brake.braked``: every cone's
    sampled-data condition, within the rotors' limits; brake: its inputs of the tick, or None).
    """
    if brake is None or model.brake is None or not cast(ConeEval, out.cones).s.shape[-1]:
        return out
    cfg = model.config
    # (a brake is built only with the rotors' limits: ``ApproachBrake`` in ``core.law.control``)
    b = braked(model.brake, cfg.cones, model.J_inv, cast(Polytope, cfg.moment_limits),
               brake, out.u)
    return out._replace(u=b.u, braking=b.braking, brake_unmet=b.unmet)


DELAY_ROBUST = Law(barrier=True, widened=True, filter=approach_brake)
