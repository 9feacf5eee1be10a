"""Headless closed loop: ``scenario CONFIG.yaml --out DIR [--duration S]``.

A scenario file is a ROS 2 parameter file with ``/**`` (shared), ``controller:``, ``sim:`` and
optionally ``scenario:`` sections; the parameters are those of ``geoctl_ros.params``. The
controller runs at ``rate_hz`` with a zero-order hold on its moment; the simulator integrates at
``integration_rate_hz`` (an integer multiple). Writes DIR/summary.json, DIR/history.csv (one row
per control step) and PNG plots like the paper's figures.

``scenario.latency`` delays the measurements: at each control step the controller sees the
simulated state of ``latency`` seconds before (noise added to that state), as a motion-capture
and IMU chain with that delay would deliver it; ``scenario.stalls`` hold samples back for a
while (the controller flies on its last one, older by the stall). ``scenario.tick_jitter`` makes
the control steps late, as a busy machine's timer does: each command is held until the next step
comes.
"""
import argparse
import collections
from dataclasses import dataclass
import json
import math
import os
import sys
import time

import numpy as np

from geoctl_ros.core import so3
from geoctl_ros.core.control import SetpointRejected
from geoctl_ros.core.gains import gain_condition
from geoctl_ros.core.loop import ControlLoop
from geoctl_ros.core.mechanics import gravity_moment
from geoctl_ros.core.stats import settle_time
from geoctl_ros.params import (
    CONTROLLER,
    SCENARIO,
    SIM,
    ConfigError,
    controller_config,
    controller_setup,
    load_parameter_file,
    node_overrides,
    resolve,
    testbed_sim,
)
from geoctl_ros.tools import plots as plotting


@dataclass
class Scenario:
    """A loaded, validated scenario."""

    name: str
    controller: dict   # resolved controller parameters
    sim: dict          # resolved sim parameters
    options: dict      # resolved scenario parameters (duration, title)


def load(path):
    """Load and validate a scenario file; raises ConfigError naming every bad parameter."""
    name = os.path.splitext(os.path.basename(str(path)))[0]
    return from_sections(load_parameter_file(path), name)


def from_sections(sections, name):
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


def hold_steps(steps, n_sub, jitter, seed):
    """How many integration steps each control step's command is held, for a run of ``steps``
    periods of n_sub integration steps: n_sub each, or with jitter (in integration steps, > 0)
    n_sub plus a uniform random whole number in 0..jitter, as on a machine too busy to run the
    loop on time: the steps come late, one after the other, and fewer fit in the run. From a
    stream of its own of ``seed``, so the noise is the same with and without it.
    """
    if jitter <= 0.0:
        return np.full(steps, n_sub)
    holds = n_sub + np.random.default_rng([seed, 1]).integers(0, int(round(jitter)) + 1, steps)
    starts = np.cumsum(holds) - holds
    return holds[starts < steps * n_sub]


def stalled_steps(options, steps, dt):
    """Per control step, whether the inputs stall there (scenario stalls.start and
    .duration): no new sample reaches the controller at a step within [start, start + duration).
    """
    k = np.arange(steps) * dt
    out = np.zeros(steps, dtype=bool)
    for start, length in zip(options['stalls.start'], options['stalls.duration']):
        out |= (k >= start) & (k < start + length)
    return out


@dataclass
class Result:
    scenario: Scenario
    columns: list
    history: np.ndarray     # one row per control step
    summary: dict


def run(scenario, duration=None):
    """Run the closed loop; returns a Result with the history and the summary.

    Each control step the controller sees the simulator's measurements (with their noise); with
    rotor actuation its moment goes through the mixer (allocation, thrust curve) and the integer
    commands drive the simulated motors, otherwise the moment acts directly. Either is held over
    the control period while the simulator integrates at its own rate.
    """
    setup = controller_setup(scenario.controller)
    loop = ControlLoop(setup)            # the controller node's logic, minus ROS
    controller, ccfg = loop.controller, setup.config
    sim = testbed_sim(scenario.sim)
    rotors = sim.actuator is not None
    mix = setup.mixer
    pcfg = sim.plant.config
    rate = scenario.controller['rate_hz']
    n_sub = int(round(scenario.sim['integration_rate_hz'] / rate))
    dt, h = 1.0 / rate, 1.0 / (rate * n_sub)
    duration = scenario.options['duration'] if duration is None else duration
    # each command is held until the next step: a period, or longer with scenario.tick_jitter
    holds = hold_steps(int(round(duration * rate)), n_sub, scenario.options['tick_jitter'] / h,
                       scenario.sim['noise.seed'])
    steps = len(holds)
    cones = ccfg.cones
    names = cones.names
    n_dbar = ccfg.n_params
    n_rot = mix.allocator.count if rotors else 0
    m_rho_true = pcfg.m_rho
    m_rho_model = ccfg.m_rho if ccfg.gravity_compensation else np.zeros(3)

    columns = (['t', 'qx', 'qy', 'qz', 'qw', 'wx', 'wy', 'wz', 'eR_x', 'eR_y', 'eR_z', 'psi',
                'u_x', 'u_y', 'u_z']
               + ['dbar_%d' % i for i in range(n_dbar)]
               + ['dtrue_%d' % i for i in range(n_dbar)]
               + ['angle_%s' % n for n in names]
               + ['cmd_%d' % (i + 1) for i in range(n_rot)]
               + ['thrust_%d' % (i + 1) for i in range(n_rot)]
               + (['moment_lost'] if rotors else []))
    hist = np.empty((steps, len(columns)))
    plant = sim.plant
    min_angle = cones.angles_deg(plant.R)          # then after every integration step
    saturated_steps = 0
    # the states of the last `delay` integration steps: the oldest is what the sensors report
    delay = int(round(scenario.options['latency'] * scenario.sim['integration_rate_hz']))
    past = collections.deque([(plant.R, plant.Omega)], maxlen=delay + 1)
    stalled = stalled_steps(scenario.options, steps, dt)
    t0 = time.perf_counter()
    for k in range(steps):
        R, t = plant.R, plant.t
        R_seen, Omega_seen = past[0]
        # captured `latency` before (before the start, the testbed sat at its initial state)
        seen_delay = delay * h
        stamp = t - seen_delay
        q_seen = so3.rot_to_quat(sim.measure_attitude(R_seen))         # (drawn even when the
        w_seen = sim.measure_angular_velocity(Omega_seen)               # sample stalls)
        if not stalled[k]:
            loop.offer_pose(q_seen, stamp, t, delay=seen_delay)
            loop.offer_angular_velocity(w_seen, stamp, t, delay=seen_delay)
        if k == 0:
            loop.arm(t)                  # armed from the start; the schedule runs from here
        tick = loop.tick(t, dt)
        out = tick.control
        # What the controller does not model: disturbance plus uncompensated gravity moment, or
        # with the constant+cog model, the disturbance and the error in m*rho separately.
        if n_dbar == 3:
            truth = pcfg.disturbance(t) + gravity_moment(R, m_rho_true - m_rho_model, pcfg.gravity)
        else:
            truth = np.concatenate((pcfg.disturbance(t), m_rho_true - m_rho_model))
        angles = cones.angles_deg(R)
        row = [[t], so3.rot_to_quat(R), plant.Omega, out.e_R, [out.psi], out.u, out.delta_bar,
               truth, angles]
        if rotors:
            motors = tick.motors
            command = motors.commands
            saturated_steps += motors.allocation.saturated
            row += [command, sim.actuator.thrusts,
                    [np.linalg.norm(motors.allocation.moment_lost)]]
        else:
            command = out.u
        hist[k] = np.concatenate(row)
        for _ in range(holds[k]):
            sim.step(command, h)
            past.append((plant.R, plant.Omega))
            if len(cones):
                min_angle = np.minimum(min_angle, cones.angles_deg(plant.R))
        if not np.all(np.isfinite(plant.Omega)):
            raise FloatingPointError('simulation diverged at t = %.3f s' % plant.t)
    wall = time.perf_counter() - t0

    settle = settle_time(hist[:, 0], hist[:, columns.index('psi')]) if steps else 0.0
    R_end = plant.R
    final = controller.step(R_end, plant.Omega, dt, adapt=False)
    theta_deg = np.degrees(cones.theta)
    summary = {
        'scenario': scenario.name,
        'title': scenario.options['title'],
        'min_cone_angle_deg': {n: float(a) for n, a in zip(names, min_angle)},
        'cone_half_angle_deg': {n: float(a) for n, a in zip(names, theta_deg)},
        'constraint_violated': bool(np.any(min_angle <= theta_deg)),
        'final_psi': float(final.psi),
        'final_attitude_error_deg': math.degrees(so3.angle(controller.R_d.T @ R_end)),
        'final_eR_norm': float(np.linalg.norm(final.e_R)),
        'final_angular_velocity_norm': float(np.linalg.norm(plant.Omega)),
        'final_disturbance_estimate': [float(v) for v in controller.delta_bar],
        'settle_time_s': settle,
        'max_abs_moment_Nm': float(np.abs(hist[:, 12:15]).max()) if steps else 0.0,
        'control_steps': steps,
        'wall_time_s': wall,
        'gain_check': gain_condition(ccfg).message(),
    }
    if rotors:
        cmd = hist[:, [columns.index('cmd_%d' % (i + 1)) for i in range(n_rot)]]
        summary.update({
            'actuation': 'rotors',
            'max_command': int(cmd.max()) if steps else 0,
            'min_command': int(cmd.min()) if steps else 0,
            'saturated_fraction': saturated_steps / max(steps, 1),
            'max_moment_lost_Nm': float(hist[:, columns.index('moment_lost')].max()),
            'airframe_warnings': mix.allocator.health.warnings,
        })
    return Result(scenario, columns, hist, summary)


def write(result, out_dir, plots=True):
    """Write summary.json, history.csv and (if plots) the PNG figures into out_dir."""
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, 'summary.json'), 'w') as f:
        json.dump(result.summary, f, indent=2)
        f.write('\n')
    np.savetxt(os.path.join(out_dir, 'history.csv'), result.history, delimiter=',',
               header=','.join(result.columns), comments='', fmt='%.9g')
    if plots:
        plotting.scenario_figures(result, out_dir)


def _output_problem(out_dir):
    """Why out_dir cannot take the results (a short phrase), or None; creates it."""
    try:
        os.makedirs(out_dir, exist_ok=True)
    except OSError as e:
        return 'cannot be created (%s)' % (e.strerror or e)
    if not os.access(out_dir, os.W_OK):
        return 'is not writable'
    return None


def main(argv=None):
    parser = argparse.ArgumentParser(prog='scenario', description=__doc__.split('\n\n')[0])
    parser.add_argument('config', help='scenario file (ROS 2 parameter YAML)')
    parser.add_argument('--out', required=True, help='output directory')
    parser.add_argument('--duration', type=float, help="simulated seconds (default: the file's)")
    parser.add_argument('--no-plots', action='store_true', help='skip the PNG figures')
    args = parser.parse_args(argv)
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        parser.error('--duration must be a positive number of seconds')
    try:
        scenario = load(args.config)
    except ConfigError as e:
        if len(e.errors) == 1 and e.errors[0][0] == str(args.config):
            print('scenario: %s: %s' % e.errors[0], file=sys.stderr)      # the file itself
        else:
            print('scenario: %s: %s' % (args.config, e), file=sys.stderr)
        return 2
    problem = _output_problem(args.out)
    if problem:
        print('scenario: --out %s: %s' % (args.out, problem), file=sys.stderr)
        return 2
    check = gain_condition(controller_config(scenario.controller))
    if not check.ok:
        print('warning: ' + check.message(), file=sys.stderr)
    try:
        result = run(scenario, args.duration)
    except SetpointRejected as e:
        print('scenario: %s: %s' % (args.config, e), file=sys.stderr)
        return 2
    try:
        write(result, args.out, plots=not args.no_plots)
    except OSError as e:
        print('scenario: --out %s: %s' % (args.out, e.strerror or e), file=sys.stderr)
        return 2
    s = result.summary
    print('%s: %d steps in %.2f s wall; final attitude error %.3g deg, Psi %.3g, settle %s s; '
          'constraint %s' % (scenario.name, s['control_steps'], s['wall_time_s'],
                             s['final_attitude_error_deg'], s['final_psi'], s['settle_time_s'],
                             'VIOLATED' if s['constraint_violated'] else 'kept'))
    for n, a in s['min_cone_angle_deg'].items():
        print('  cone %-12s min angle %7.2f deg (half-angle %.1f)' % (
            n, a, s['cone_half_angle_deg'][n]))
    print('  wrote %s' % args.out)
    return 0


if __name__ == '__main__':
    sys.exit(main())
