"""Many scenario runs at once: the closed loop of ``geoctl_ros.tools.scenario`` on a batch.

``run_batch(scenarios)`` flies every scenario of the list together, as arrays with a leading batch
axis, through the same classes a single run uses (``AttitudeController``, ``Mixer``, ``Plant``,
``RotorActuator``: their formulas take batches). Per run it may differ from the others in what a
campaign varies: the cones (same number of cones in one batch), the set point, the initial attitude
and angular velocity, the true mass, inertia and centre-of-mass offset, the constant disturbance,
the noise seed and gyro bias, and the latency. Everything else (gains, airframe, rates, noise
levels, duration) must be the same; ``run_batch`` says which parameter differs otherwise.

The loop is the scenario runner's, step for step: each control step the controller sees the state
``latency`` before, with the motion-capture and gyro noise of the run's own seed drawn in the same
order as ``TestbedSim`` draws it; its moment goes through the mixer and the integer commands are
held over the control period while the plant integrates. It leaves out what a scenario file cannot
change in flight: the node's input checks, gap bridging and set-point schedule (a campaign's
scenario has one set point and no schedule). So a run of a batch and the same file through
``scenario`` agree to rounding (test_campaign.py measures by how much).
"""
from dataclasses import dataclass, replace
import math
import time

import numpy as np

from geoctl_ros.core import so3
from geoctl_ros.core.cones import ConeSet
from geoctl_ros.core.control import AttitudeController
from geoctl_ros.core.step import ControlTick
from geoctl_ros.params import (
    CONTROLLER,
    SIM,
    airframe,
    cone_set,
    controller_setup,
    setpoint_rotation,
)
from geoctl_ros.sim.plant import Disturbance, Plant, PlantConfig
from geoctl_ros.sim.testbed import RotorActuator
from geoctl_ros.tools.scenario import stalled_steps

SETTLED_DEG = 5.0       # attitude error below which a run has converged (at the end) or settled

# What may differ between the runs of a batch (everything else must be equal).
PER_RUN = {
    CONTROLLER: ('setpoint', 'unmodelled_moment_max'),     # (a set-point check, not in flight)
    SIM: ('initial_attitude', 'initial_angular_velocity', 'mass', 'inertia', 'cog_offset',
          'disturbance.constant', 'noise.seed', 'noise.gyro_bias'),
}


@dataclass
class BatchResult:
    """Per-run figures of a batch (arrays with one entry per run, in the scenarios' order)."""

    names: list
    min_margin_deg: np.ndarray     # (runs, cones): closest approach to each cone, after every
                                   # integration step (angle to its axis minus its half-angle)
    violated: np.ndarray           # (runs,): the sensor reached or entered a cone
    final_error_deg: np.ndarray    # (runs,): attitude error at the end
    final_psi: np.ndarray          # (runs,)
    saturated_s: np.ndarray        # (runs,): time with the allocation saturated
    max_rate: np.ndarray           # (runs,): largest measured |Omega| (rad/s)
    settle_s: np.ndarray           # (runs,): the time from which the attitude error stays below
                                   # SETTLED_DEG (core.stats.settle_time's rule on the control
                                   # steps; NaN: not below at the end)
    margin_series: np.ndarray      # (steps, runs): min cone margin at each control step (None
                                   # unless asked for: series=True)
    sensor_series: np.ndarray      # (steps, runs, 3): sensor direction R r, world frame (float32;
                                   # None unless asked for)
    dt: float
    wall_s: float = 0.0


def _differing(scenarios):
    """The first shared parameter that differs between the scenarios, or None."""
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
        if s.options['duration'] != first.options['duration']:
            return 'scenario: duration (%s and %s)' % (first.name, s.name)
        if len(s.controller['cones.names']) != len(first.controller['cones.names']):
            return 'the number of cones (%s and %s)' % (first.name, s.name)
    return None


def _cos_error(R_d, R):
    """The cosine of the attitude error angle between R_d and R, per run."""
    return 0.5 * (np.trace(so3.transpose(R_d) @ R, axis1=-2, axis2=-1) - 1.0)


def run_batch(scenarios, progress=None, series=True):
    """Fly the scenarios together; a BatchResult. progress(fraction) is called now and then.
    series: keep the margin and sensor direction at every control step (the figures of a few
    runs; a campaign's batches leave them out and fly its worst runs again for them).
    """
    problem = _differing(scenarios)
    if problem:
        raise ValueError('a batch shares everything but %s; differs: %s'
                         % (', '.join(PER_RUN[CONTROLLER] + PER_RUN[SIM]), problem))
    first = scenarios[0]
    cv, sv = first.controller, first.sim
    if sv['actuation'] != 'rotors':
        raise ValueError('run_batch flies rotor actuation only')
    n = len(scenarios)
    setup = controller_setup(cv)                                     # gains, model, mixer
    names = cv['cones.names']

    def stack(node, key):
        return np.array([getattr(s, node)[key] for s in scenarios], dtype=float)

    shared = setup.config.cones
    per_run = [cone_set(s.controller) for s in scenarios]
    cones = ConeSet(shared.r, np.array([c.V for c in per_run]).reshape(n, len(names), 3),
                    np.array([c.theta for c in per_run]).reshape(n, len(names)),
                    shared.alpha, shared.floor, names, shared.guard)
    controller = AttitudeController(replace(setup.config, cones=cones))
    controller.R_d = np.array([setpoint_rotation(s.controller) for s in scenarios])
    controller.delta_bar = np.zeros((n, setup.config.n_params))

    plant = Plant(PlantConfig(inertia=stack('sim', 'inertia').reshape(n, 3, 3),
                              mass=stack('sim', 'mass'), cog_offset=stack('sim', 'cog_offset'),
                              gravity=sv['gravity'],
                              disturbance=Disturbance(stack('sim', 'disturbance.constant'),
                                                      np.zeros(3), 0.0)),
                  np.array([so3.quat_to_rot(s.sim['initial_attitude']) for s in scenarios]),
                  stack('sim', 'initial_angular_velocity'))
    if any(s.options['tick_jitter'] > 0.0 for s in scenarios):
        raise ValueError('run_batch flies on-time control steps only (scenario: tick_jitter)')
    if sv['disturbance.amplitude'].any():
        raise ValueError('run_batch flies constant disturbances only')
    geometry, curve, failed = airframe(sv)
    actuator = RotorActuator(geometry, stack('sim', 'cog_offset'), curve,
                             sv['motor_time_constant'], failed)

    rate = cv['rate_hz']
    n_sub = int(round(sv['integration_rate_hz'] / rate))
    dt, h = 1.0 / rate, 1.0 / (rate * n_sub)
    steps = int(round(first.options['duration'] * rate))
    # noise, drawn per run in TestbedSim's order: per control step the attitude's 3, the gyro's 3
    sigmas = [math.radians(sv['noise.attitude_deg']), sv['noise.angular_velocity']]
    drawn = [i for i, sigma in enumerate(sigmas) if sigma > 0.0]
    noise = np.zeros((2, steps, n, 3))
    for j, s in enumerate(scenarios):
        z = np.random.default_rng(s.sim['noise.seed']).standard_normal((steps, len(drawn), 3))
        for slot, i in enumerate(drawn):
            noise[i, :, j] = sigmas[i] * z[:, slot]
    gyro_bias = stack('sim', 'noise.gyro_bias')
    # latency: a ring of the last states, one per integration step
    delay = np.array([int(round(s.options['latency'] * sv['integration_rate_hz']))
                      for s in scenarios])
    ring = int(delay.max()) + 1
    R_past = np.repeat(plant.R[None], ring, axis=0)
    W_past = np.repeat(plant.Omega[None], ring, axis=0)
    runs = np.arange(n)

    # the control tick of ControlLoop's (geoctl_ros.core.step), every step on time, each sample
    # received at the tick: its age the latency, from its stamp (age_from_stamps), else the
    # measurement_delay the controller assumes
    stamped = setup.loop.age_from_stamps
    tick = ControlTick(controller, setup.mixer, 0.0 if stamped else setup.loop.measurement_delay)
    ages = (0.0, 0.0)
    # input stalls: no new sample at a stalled step, the run flies on its last one (as the loop's
    # streams age it: its delay at receipt plus the time since, on the plant's clock)
    stalled = np.stack([stalled_steps(s.options, steps, dt) for s in scenarios], axis=1)
    any_stall = bool(stalled.any())
    receipt = np.zeros(n)
    R_seen, W_seen = plant.R, plant.Omega
    min_margin = cones.margins_deg(plant.R)
    margin_series = np.empty((steps, n)) if series else None
    sensor_series = np.empty((steps, n, 3), dtype=np.float32) if series else None
    last_unsettled = np.full(n, -1)        # the last control step with the error >= SETTLED_DEG
    cos_settled = math.cos(math.radians(SETTLED_DEG))
    saturated = np.zeros(n)
    max_rate = np.zeros(n)
    j = 0                                                     # integration steps so far
    t0 = time.perf_counter()
    for k in range(steps):
        seen = np.maximum(j - delay, 0) % ring
        R_new = R_past[seen, runs] @ so3.exp(noise[0, k])
        W_new = W_past[seen, runs] + gyro_bias + noise[1, k]
        if any_stall:
            fresh = ~stalled[k]
            R_seen = np.where(fresh[:, None, None], R_new, R_seen)
            W_seen = np.where(fresh[:, None], W_new, W_seen)
            receipt = np.where(fresh, plant.t, receipt)
            waited = np.maximum(plant.t - receipt, 0.0)
            age = delay * h + waited if stamped else waited
            ages = (age, age)
        else:
            R_seen, W_seen = R_new, W_new
            if stamped:      # (before the start, the testbed sat at its initial state)
                ages = (delay * h,) * 2
        max_rate = np.maximum(max_rate, np.linalg.norm(W_seen, axis=-1))
        out, motors = tick(R_seen, W_seen, dt, ages=ages)
        saturated += motors.allocation.saturated
        last_unsettled[_cos_error(controller.R_d, plant.R) <= cos_settled] = k
        if series:
            margin_series[k] = cones.margins_deg(plant.R).min(axis=-1)
            sensor_series[k] = so3.matvec(plant.R, cones.r)
        for _ in range(n_sub):
            plant.step(actuator.moment(motors.commands, h), h)
            j += 1
            R_past[j % ring], W_past[j % ring] = plant.R, plant.Omega
            min_margin = np.minimum(min_margin, cones.margins_deg(plant.R))
        if progress is not None and (k + 1) % 100 == 0:
            progress((k + 1) / steps)
    final = controller.step(plant.R, plant.Omega, dt, adapt=False)
    cos_err = np.clip(_cos_error(controller.R_d, plant.R), -1.0, 1.0)
    return BatchResult(
        names=[s.name for s in scenarios], min_margin_deg=min_margin,
        violated=np.any(min_margin <= 0.0, axis=-1),
        final_error_deg=np.degrees(np.arccos(cos_err)),
        final_psi=np.asarray(final.psi), saturated_s=saturated * dt, max_rate=max_rate,
        # settle_time's rule on the steps' times k dt: the step after the last unsettled one
        settle_s=np.where(last_unsettled == steps - 1, np.nan, (last_unsettled + 1) * dt),
        margin_series=margin_series, sensor_series=sensor_series, dt=dt,
        wall_s=time.perf_counter() - t0)
