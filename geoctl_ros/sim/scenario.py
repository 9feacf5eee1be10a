"""A scenario: a scenario file's parameters, validated, and its run through the closed loop.

A scenario file is a ROS 2 parameter file with ``/**`` (shared), ``controller:``, ``sim:`` and
optionally ``scenario:`` sections; the parameters are those of ``geoctl_ros.params``. ``run``
flies it as a batch of one through ``geoctl_ros.sim.closed_loop`` (its docstring says what the
loop models: latency, stalls, late steps, rotors or torque) and sums the flight up.
"""
from dataclasses import dataclass
import os
from typing import Optional

import numpy as np

from geoctl_ros.core.law.gains import gain_condition
from geoctl_ros.params import (
    CONTROLLER,
    SCENARIO,
    SIM,
    ConfigError,
    controller_setup,
    load_parameter_file,
    node_overrides,
    resolve,
)
from geoctl_ros.params.scenario import Scenario
from geoctl_ros.sim.build import testbed_sim
from geoctl_ros.sim.closed_loop import fly

__all__ = ['Result', 'Scenario', 'from_sections', 'load', 'run']   # (Scenario: params.scenario's)


def load(path: str) -> Scenario:
    """Load and validate a scenario file; raises ConfigError naming every bad parameter."""
    name = os.path.splitext(os.path.basename(str(path)))[0]
    return from_sections(load_parameter_file(path), name)


def from_sections(sections: dict, name: str) -> Scenario:
    """A validated Scenario from parameter-file sections ({'/**' or node: flat parameters}), as
    ``load`` reads them from a file; raises ConfigError naming every bad parameter.
    """
    errors = []
    resolved = {}
    for node in (CONTROLLER, SIM, SCENARIO):
        try:
            resolved[node] = resolve(node, node_overrides(sections, node))
        except ConfigError as e:
            errors += [('%s: %s' % (node, name), reason) for name, reason in e.errors]
    if errors:
        raise ConfigError(errors)
    ratio = resolved[SIM]['integration_rate_hz'] / resolved[CONTROLLER]['rate_hz']
    if ratio < 1.0 or abs(ratio - round(ratio)) > 1e-9:
        raise ConfigError([('sim: integration_rate_hz', 'must be an integer multiple of the '
                            'controller rate_hz (%g / %g)' % (resolved[SIM]['integration_rate_hz'],
                                                              resolved[CONTROLLER]['rate_hz']))])
    if len(resolved[SCENARIO]['stalls.start']) != len(resolved[SCENARIO]['stalls.duration']):
        raise ConfigError([('scenario: stalls.duration', 'needs one value per stalls.start')])
    delay = resolved[SCENARIO]['latency'] * resolved[SIM]['integration_rate_hz']
    if abs(delay - round(delay)) > 1e-6:
        raise ConfigError([('scenario: latency', 'must be a whole number of integration steps '
                            '(1 / %g s)' % resolved[SIM]['integration_rate_hz'])])
    for node, build in ((CONTROLLER, controller_setup), (SIM, testbed_sim)):
        try:
            build(resolved[node])
        except ConfigError as e:
            errors += [('%s: %s' % (node, name), reason) for name, reason in e.errors]
    if errors:
        raise ConfigError(errors)
    return Scenario(name, resolved[CONTROLLER], resolved[SIM], resolved[SCENARIO])


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
        'title': scenario.options['title'],
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
    if scenario.sim['actuation'] == 'rotors':
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
