"""A scenario: a scenario file's parameters, resolved and validated (``load``, ``from_sections``;
``on_airframe``: a file's flown on another's airframe), with its typed set-ups: the run's
conditions (``ScenarioOptions``) and its testbed (``geoctl_ros.params.testbed.TestbedSetup``).
``geoctl_ros.sim.scenario.run`` flies one, and ``geoctl_ros.sim.closed_loop.fly`` a batch, whose
runs may differ only in ``PER_RUN``.

A scenario file is a ROS 2 parameter file with ``/**`` (shared), ``controller:``, ``sim:`` and
optionally ``scenario:`` sections; the parameters are those of ``geoctl_ros.params``.
"""
from dataclasses import dataclass
import os
from typing import List, Optional, Tuple

import numpy as np

from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.params.build import cone_set, controller_setup, setpoint_rotation
from geoctl_ros.params.files import load_parameter_file, node_overrides
from geoctl_ros.params.param import CONTROLLER, SCENARIO, SIM, ConfigError
from geoctl_ros.params.schema import AIRFRAME_NAMES, BY_NAME, schema_for
from geoctl_ros.params.testbed import TestbedSetup, testbed_setup
from geoctl_ros.params.validate import resolve

# What may differ between the runs of a batch (everything else must be equal).
PER_RUN = {
    CONTROLLER: ('setpoint', 'unmodelled_moment_max'),     # (a set-point check, not in flight)
    SIM: ('initial_attitude', 'initial_angular_velocity', 'mass', 'inertia', 'cog_offset',
          'disturbance.constant', 'noise.seed', 'noise.gyro_bias'),
}


@dataclass(frozen=True)
class ScenarioOptions:
    """How a scenario is flown (its ``scenario:`` section), typed."""

    title: str
    duration: float                       # s
    latency: float                        # s: how old every measurement is when it arrives
    tick_jitter: float                    # s: how late a control step may come
    stalls: Tuple[Tuple[float, float], ...]   # (start s, length s): no input reaches the loop
    tick_jitter_seed: int = -1            # the lateness's seed (-1: noise.seed)
    start: str = 'held'                   # held through the spool-up, or resting (free)

    def stalled(self, times: np.ndarray) -> np.ndarray:
        """Per control step (at times), whether the inputs stall there: no new sample reaches
        the controller at a step within [start, start + length).
        """
        out = np.zeros(len(times), dtype=bool)
        for start, length in self.stalls:
            out |= (times >= start) & (times < start + length)
        return out


def scenario_options(values: dict) -> ScenarioOptions:
    """The ScenarioOptions of resolved scenario parameters."""
    return ScenarioOptions(values['title'], values['duration'], values['latency'],
                           values['tick_jitter'],
                           tuple(zip(values['stalls.start'], values['stalls.duration'])),
                           values['tick_jitter_seed'], values['start'])


@dataclass
class Scenario:
    """A loaded, validated scenario: its resolved parameters per node (what its file holds) and
    their typed set-ups.
    """

    name: str
    controller: dict   # resolved controller parameters
    sim: dict          # resolved sim parameters
    option_values: dict    # resolved scenario parameters

    @property
    def options(self) -> ScenarioOptions:
        """How it is flown."""
        return scenario_options(self.option_values)

    @property
    def testbed(self) -> TestbedSetup:
        """Its simulated testbed."""
        return testbed_setup(self.sim)

    @property
    def cone_names(self) -> List[str]:
        """Its cones' names."""
        return list(self.controller['cones.names'])

    def setpoint(self) -> np.ndarray:
        """R_d."""
        return setpoint_rotation(self.controller)

    def cones(self) -> ConeSet:
        """Its ConeSet."""
        return cone_set(self.controller)


def on_airframe(sections: dict, of: dict) -> dict:
    """Parameter-file sections flown on the airframe of another file's (``of``): each node's
    (the controller's, the sim's) ``AIRFRAME_NAMES`` as ``of`` resolves them (its defaults where
    it sets none) put over its own section; the rest (gains, cones, set points, noise, timing)
    stays theirs. Raises ConfigError where ``of`` does not resolve.
    """
    out = {node: dict(flat) for node, flat in sections.items()}
    for node in (CONTROLLER, SIM):
        values = resolve(node, node_overrides(of, node))
        own = {p.name for p in schema_for(node)}
        frame = {name: (values[name].tolist() if isinstance(values[name], np.ndarray)
                        else values[name]) for name in AIRFRAME_NAMES if name in own}
        keys = [k for k in (node, '/' + node) if k in out] or [node]
        for key in keys:                     # (a file may address a node either way)
            out.setdefault(key, {}).update(frame)
    return out


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
    for node, build in ((CONTROLLER, controller_setup), (SIM, testbed_setup)):
        try:
            build(resolved[node])
        except ConfigError as e:
            errors += [('%s: %s' % (node, name), reason) for name, reason in e.errors]
    if errors:
        raise ConfigError(errors)
    return Scenario(name, resolved[CONTROLLER], resolved[SIM], resolved[SCENARIO])


def tick_jitter(sections: dict) -> float:
    """The tick jitter (s) of a scenario file's sections: the runs of a batch share it."""
    return float(sections.get(SCENARIO, {}).get('tick_jitter', BY_NAME['tick_jitter'].default))


def goal_check(sections: dict) -> bool:
    """Whether a scenario file's sections (``from_sections``) keep the controller's check of the
    goal against the unlearnt moment (``unmodelled_moment_max`` not 0).
    """
    return bool(sections['controller'].get('unmodelled_moment_max', 1.0))


def turn_off_goal_check(sections: dict) -> None:
    """Turn that check off in the sections (a goal the controller refuses, flown all the same)."""
    sections['controller']['unmodelled_moment_max'] = 0.0


def differing(scenarios: List[Scenario]) -> Optional[str]:
    """The first shared parameter that differs between the scenarios of a batch, or None."""
    first = scenarios[0]
    for attr, node in (('controller', CONTROLLER), ('sim', SIM)):
        ref = getattr(first, attr)
        for s in scenarios[1:]:
            values = getattr(s, attr)
            for key, v in ref.items():
                if key in PER_RUN[node] or key.startswith('cones.'):
                    continue
                if not np.array_equal(np.asarray(v), np.asarray(values[key])):
                    return '%s: %s (%s and %s)' % (node, key, first.name, s.name)
    for s in scenarios[1:]:
        a, b = first.options, s.options
        for key, x, y in (('duration', a.duration, b.duration),
                          ('tick_jitter', a.tick_jitter, b.tick_jitter),
                          ('start', a.start, b.start)):
            if x != y:
                return 'scenario: %s (%s and %s)' % (key, first.name, s.name)
        if len(s.cone_names) != len(first.cone_names):
            return 'the number of cones (%s and %s)' % (first.name, s.name)
    return None
