"""The lab's sensors in the sim-in-the-loop: each convention or mounting the sim can emulate,
flown against the controller with today's defaults (which must refuse to arm, or fail safe in
flight, naming the mismatch) and with the matching parameters (which must fly the testbed's
manoeuvre and keep the cone).

``CASES`` holds, per case, the sim's emulation and the controller's matching parameters; the
cases whose fix is a calibration (the gyro's bias, a tilted marker set) take it from
``calibrate`` run against the sim, as the lab does. ``run_case`` flies one; ``./run sensors``
all (``geoctl_ros.cli.sensors``).
"""
import math
import os
import subprocess
import sys
import time
from typing import Dict, List, NamedTuple, Optional

import numpy as np
import rclpy

from geoctl_ros.core.geometry import so3
from geoctl_ros.params import (
    CONTROLLER,
    cone_set,
    controller_setup,
    load_parameter_file,
    node_overrides,
    resolve,
)
from geoctl_ros.sil.processes import FLY_CONFIGURED, Monitor, NodeProcess, executable
from geoctl_ros.sil.rosenv import node_env, use_node_env


class Case(NamedTuple):
    title: str
    sim: Dict[str, str]            # the sim's emulation (-p name:=value)
    matching: Dict[str, str]       # the controller's matching parameters
    calibrate: bool = False        # the matching parameters come from calibrate (HEADING_DEG)


CASES = {
    'ned_frd': Case('pose and IMU in NED/FRD',
                    {'pose_world_frame': 'ned', 'body_frame': 'frd'},
                    {'pose_world_frame': 'ned', 'body_frame': 'frd'}),
    'y_up': Case('a Y-up motion-capture frame (and its Y-up rigid body)',
                 {'pose_world_frame': 'y_up', 'marker_rotation_deg': '[90.0,0.0,0.0]'},
                 {'pose_world_frame': 'y_up', 'marker_rotation_deg': '[90.0,0.0,0.0]'}),
    'imu_yaw90': Case('the IMU mounted 90 deg off in yaw',
                      {'imu_rotation_deg': '[0.0,0.0,90.0]'},
                      {'imu_rotation_deg': '[0.0,0.0,90.0]'}),
    'marker_tilt10': Case('the marker set 10 deg off in tilt (calibrated)',
                          {'marker_rotation_deg': '[10.0,0.0,0.0]'}, {}, calibrate=True),
    'gyro_bias': Case('a gyro bias of 0.02 rad/s (calibrated)',
                      {'noise.gyro_bias': '[0.02,0.0,0.0]'}, {}, calibrate=True),
}
HEADING_DEG = 90.0      # the sim's airframe rests level, its nose 90 deg left of its ENU x axis


class Outcome(NamedTuple):
    case: str
    parameters: str                # 'defaults' or 'matching'
    armed: bool
    message: str                   # the arming reply, or the failsafe's reason
    failsafe: Optional[str]
    min_margin_deg: Optional[float]
    final_error_deg: Optional[float]


def _args(params: Dict[str, str]) -> List[str]:
    out: List[str] = []
    for k, v in params.items():
        out += ['-p', '%s:=%s' % (k, v)]
    return out


def run_calibrate(params_file: str, out: str, seconds: float = 3.0) -> Dict[str, str]:
    """Run ``calibrate`` (the real command) against the running sim; its parameters as -p
    values.
    """
    path = os.path.join(out, 'calibration.yaml')
    exe = executable('calibrate')
    cmd = ([exe] if exe else [sys.executable, '-m', 'geoctl_ros.nodes.calibrate'])
    cmd += ['--params-file', params_file, '--seconds', str(seconds), '--heading-deg',
            str(HEADING_DEG), '--out', path]
    done = subprocess.run(cmd, env=node_env(), capture_output=True, text=True, timeout=120)
    if done.returncode != 0:
        raise RuntimeError('calibrate failed: %s' % done.stderr[-2000:])
    flat = load_parameter_file(path)[CONTROLLER]
    return {k: '[%s]' % ','.join(repr(float(x)) for x in v) for k, v in flat.items()}


def run_case(name: str, matching: bool, params_file: str, out: str,
             duration: float = 15.0) -> Outcome:
    """Fly one case with the defaults or the matching parameters (module docstring)."""
    use_node_env()
    case = CASES[name]
    values = resolve(CONTROLLER, node_overrides(load_parameter_file(params_file), CONTROLLER))
    setup = controller_setup(values)
    cones = cone_set(values)
    goal = setup.schedule.rotations[-1] if len(setup.schedule) else setup.setpoint
    out = os.path.join(out, '%s_%s' % (name, 'matching' if matching else 'defaults'))
    os.makedirs(out, exist_ok=True)
    procs = [NodeProcess('sim', params_file, _args(case.sim), log_dir=out)]
    rclpy.init()
    mon = Monitor()
    try:
        extra = dict(case.matching)
        if matching and case.calibrate:
            mon.wait_for(lambda: mon.log['pose'], 30.0, 'the sim')
            extra.update(run_calibrate(params_file, out))
        procs.append(NodeProcess('controller', params_file,
                                 [*FLY_CONFIGURED, *(_args(extra) if matching else [])],
                                 log_dir=out))
        reply = mon.arm_when_ready(10.0)
        if not reply.success:
            return Outcome(name, 'matching' if matching else 'defaults', False, reply.message,
                           None, None, None)
        t_arm = time.monotonic()
        failsafe = None
        while time.monotonic() - t_arm < duration:
            mon.spin_for(0.1)
            d = mon.last_diagnostic()
            if d is not None and d.figures.failsafe:
                failsafe = d.message
                break
        t_end = time.monotonic()
        mon.arm(False)
    finally:
        mon.destroy_node()
        rclpy.try_shutdown()
        for p in procs:
            p.stop()
    Rs = [so3.quat_to_rot(q) for t, (_, q) in mon.log['true_pose'] if t_arm <= t <= t_end]
    margins = [float(np.min(cones.margins_deg(R))) for R in Rs]
    err = math.degrees(so3.angle(goal.T @ Rs[-1])) if Rs else None
    return Outcome(name, 'matching' if matching else 'defaults', True,
                   'armed', failsafe, min(margins) if margins else None, err)
