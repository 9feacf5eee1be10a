"""A scenario's run through the closed loop. A scenario (``geoctl_ros.params.scenario``: a
scenario file's parameters, validated, and their typed set-ups) is loaded with ``load``; ``run``
flies it as a batch of one through ``geoctl_ros.sim.closed_loop`` (its docstring says what the
loop models: latency, stalls, late steps, rotors or torque) and sums the flight up.
"""
from dataclasses import dataclass
from typing import Optional

import numpy as np

from geoctl_ros.core.law.gains import gain_condition
from geoctl_ros.params import controller_setup
from geoctl_ros.params.scenario import Scenario, from_sections, load
from geoctl_ros.sim.closed_loop import fly

__all__ = ['Result', 'Scenario', 'from_sections', 'load', 'run']   # (the first three: params')


@dataclass
class Result:
    scenario: Scenario
    columns: list
    history: np.ndarray     # one row per control step
    summary: dict
    flight: object          # the closed loop's Flight (a batch of one)


def _figure(x):
    """A figure for the summary: a float, or None for NaN (not reached)."""
    return None if np.isnan(x) else float(x)


def run(scenario: Scenario, duration: Optional[float] = None) -> Result:
    """Fly the scenario (a batch of one); a Result with the history and the summary."""
    flight = fly([scenario], history=True, duration=duration)
    history = flight.history
    assert history is not None           # (asked for)
    table = history.table(0)
    columns = history.columns()
    steps = len(flight.times)
    names = history.cone_names
    final = flight.final
    setup = controller_setup(scenario.controller)
    summary = {
        'scenario': scenario.name,
        'title': scenario.options.title,
        'min_cone_angle_deg': {n: float(a) for n, a in zip(names, flight.min_angle_deg[0])},
        'cone_half_angle_deg': {n: float(a) for n, a in zip(names, flight.half_angle_deg[0])},
        'constraint_violated': bool(flight.violated[0]),
        'final_psi': float(np.asarray(final.psi)[0]),
        'final_attitude_error_deg': float(flight.final_error_deg[0]),
        'final_eR_norm': float(np.linalg.norm(final.e_R[0])),
        'final_angular_velocity_norm': float(np.linalg.norm(flight.final_angular_velocity[0])),
        'final_disturbance_estimate': [float(v) for v in final.delta_bar[0]],
        'settle_time_s': _figure(flight.psi_settle_s[0]),
        'time_to_5deg_s': _figure(flight.settle_s[0]),
        'time_to_1deg_s': _figure(flight.settle_fine_s[0]),
        'max_abs_moment_Nm': float(np.abs(history.arrays['u'][:, 0]).max()) if steps else 0.0,
        'control_steps': steps,
        'wall_time_s': flight.wall_s,
        'gain_check': gain_condition(setup.config).message(),
    }
    if scenario.testbed.rotors is not None:
        cmd = history.arrays['cmd'][:, 0]
        summary.update({
            'actuation': 'rotors',
            'max_command': int(cmd.max()) if steps else 0,
            'min_command': int(cmd.min()) if steps else 0,
            'saturated_fraction': float(flight.saturated_steps[0]) / max(steps, 1),
            'max_moment_lost_Nm': float(history.arrays['moment_lost'][:, 0].max()),
            'airframe_warnings': setup.mixer.allocator.health.warnings,
        })
    return Result(scenario, columns, table, summary, flight)
