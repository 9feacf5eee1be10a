"""The sim-in-the-loop flight of ``./run demo`` (``geoctl_ros.cli.demo``): the ``sim`` and
``controller`` nodes as two processes on a parameter file, armed through the controller's
``~/arm`` service (the arming flying the file's set point: ``FLY_CONFIGURED``), recorded,
disarmed, and summed up (the closest approach from the sim's true attitude, the final error,
the loop's rate and latency from the controller's diagnostics, and the command stream a
subscriber sees).
"""
import json
import math
import os
import sys
import time

import numpy as np
import rclpy

from geoctl_ros import plots
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.telemetry.diagnostics import aggregate_ms
from geoctl_ros.esc.virtual import VirtualEscBus
from geoctl_ros.nodes.recorder import default_path
from geoctl_ros.params import (
    CONTROLLER,
    ESC,
    cone_set,
    controller_setup,
    load_parameter_file,
    node_overrides,
    resolve,
)
from geoctl_ros.params.esc import esc_config
from geoctl_ros.sil.processes import FLY_CONFIGURED, Monitor, NodeProcess
from geoctl_ros.sil.rosenv import use_node_env


def _diag_stats(diags, name):
    """The controller's windows of one diagnostics figure (a Figures field) as one, ms."""
    w = aggregate_ms(diags, name)
    return None if w is None else {k + '_ms': v for k, v in w._asdict().items()}


def fly(params_file, out, duration, monitor_factory=None, mavlink=None, record=True,
        esc=False):
    """Run sim + controller as processes, arm, fly duration seconds; returns the summary. With
    record, ``record`` writes the flight to a bag under out/records (its path in the summary).
    With esc, the ``esc_i2c`` node writes the commands to a virtual ESC bus (out/esc_bus) that
    the sim reads instead of ``motor_commands``: the flight goes through the ESCs' byte encoding
    and the node's watchdog, and the summary says what the ESCs were told after the disarm.
    """
    use_node_env()
    values = resolve(CONTROLLER, node_overrides(load_parameter_file(params_file), CONTROLLER))
    setup = controller_setup(values)
    cones = cone_set(values)
    final_setpoint = (setup.schedule.rotations[-1] if len(setup.schedule) else setup.setpoint)
    os.makedirs(out, exist_ok=True)
    bus_args = ()
    if esc:
        bus_path = os.path.abspath(os.path.join(out, 'esc_bus'))
        if os.path.exists(bus_path):
            os.unlink(bus_path)
        bus_args = ('-p', 'esc.virtual_bus:=' + bus_path)
    procs = [NodeProcess('sim', params_file, bus_args, log_dir=out),
             NodeProcess('controller', params_file, FLY_CONFIGURED, log_dir=out)]
    if esc:             # first in the list: stopped (zero to every ESC) before the sim goes
        procs.insert(0, NodeProcess('esc_i2c', params_file,
                                    bus_args + ('-p', 'esc.probe_timeout:=20.0'), log_dir=out))
    if mavlink:        # a ground station on this machine can watch the flight
        procs.append(NodeProcess('mavlink_bridge', None, ('-p', 'mavlink.url:=' + mavlink),
                                 log_dir=out))
    bag_path = os.path.join(out, default_path()) if record else None
    if record:
        recorder = NodeProcess('record', None, ('-p', 'record.path:=' + bag_path), log_dir=out)
        procs.append(recorder)
    rclpy.init()
    mon = (monitor_factory or Monitor)()
    try:
        if record:          # from the first true pose and diagnostics on: recorded whole
            mon.wait_for(lambda: all('first message on %s' % t in recorder.output()
                                     for t in ('/sim/true_pose', '/diagnostics'))
                         or recorder.proc.poll() is not None, 30.0, 'the recorder')
        reply = mon.arm_when_ready(30.0)
        if not reply.success:
            raise RuntimeError(reply.message)
        t_arm = time.monotonic()
        print('armed; flying %.0f s ...' % duration, file=sys.stderr)
        mon.spin_for(duration)
        t_end = time.monotonic()
        mon.arm(False)
        mon.spin_for(0.5)
        after_disarm = mon.last('motors')
        if esc:             # what the ESCs were told last, from the bus itself
            bus = VirtualEscBus(bus_path, esc_config(resolve(ESC, {})).addresses)
            after_disarm = [data[0] for data, _ in bus.setpoints()]
            bus.close()
    finally:
        mon.destroy_node()
        rclpy.try_shutdown()
        codes = [p.stop() for p in procs]

    flight = [(t - t_arm, v[1]) for t, v in mon.log['true_pose'] if t_arm <= t <= t_end]
    t = np.array([x[0] for x in flight])
    Rs = [so3.quat_to_rot(q) for _, q in flight]
    angles = np.array([cones.angles_deg(R) for R in Rs]).reshape(len(Rs), len(cones))
    err = np.array([math.degrees(so3.angle(final_setpoint.T @ R)) for R in Rs])
    diags = [d for tt, d in mon.log['diagnostics'] if t_arm + 1.0 <= tt <= t_end]
    cmd_times = np.array([tt for tt, _ in mon.log['motors'] if t_arm <= tt <= t_end])
    gaps = np.diff(cmd_times) * 1e3 if len(cmd_times) > 1 else np.array([0.0])
    commands = np.array([c for tt, c in mon.log['motors'] if t_arm <= tt <= t_end])
    psi = [(tt - t_arm, v) for tt, v in mon.log['psi'] if t_arm <= tt <= t_end]
    summary = {
        'params_file': str(params_file),
        'flight_s': duration,
        'min_cone_angle_deg': {n: float(angles[:, i].min()) for i, n in enumerate(cones.names)},
        'cone_half_angle_deg': {n: float(math.degrees(th)) for n, th in zip(cones.names,
                                                                            cones.theta)},
        'min_cone_margin_deg': float((angles - np.degrees(cones.theta)).min()) if len(cones)
        else None,
        'final_attitude_error_deg': float(err[-1]),
        'loop_period': _diag_stats(diags, 'loop_period'),
        'step_compute': _diag_stats(diags, 'tick_to_command'),
        'pose_to_command_latency': _diag_stats(diags, 'pose_to_command_latency'),
        'commands_seen_by_subscriber': {'count': int(len(cmd_times)),
                                        'frequency_hz': float(1e3 / gaps.mean()),
                                        'gap_std_ms': float(gaps.std()),
                                        'gap_max_ms': float(gaps.max())},
        'commands_zero_after_disarm': bool(after_disarm is not None and not any(after_disarm)),
        'node_exit_codes': codes,
        'record': bag_path,
        'through': 'virtual ESC bus' if esc else 'motor_commands',
    }
    with open(os.path.join(out, 'sil_summary.json'), 'w') as f:
        json.dump(summary, f, indent=2)
        f.write('\n')
    if plots.available('demo'):
        from geoctl_ros.plots import flight as flight_plots  # noqa: PLC0415  (matplotlib)
        flight_plots.sil_figure(out, t, angles, cones, err, psi, cmd_times - t_arm, commands)
    return summary

