"""The controller node's logic without ROS: checked inputs, arming, set points, step, mixing.

The node turns messages into calls of this class and its results into messages; every decision
(refuse a sample, refuse to arm, fail safe, adopt a set point, freeze adaptation) is made here, so
it is tested without rclpy.
"""
from dataclasses import dataclass

import numpy as np

from geoctl_ros import so3
from geoctl_ros.control import AttitudeController, SetpointRejected
from geoctl_ros.safety import (Stream, Supervisor, angular_velocity_problem, quaternion_problem)


@dataclass
class Tick:
    """One control tick's results for the node to publish."""

    control: object          # ControlOutput, or None before the first pose and rate
    motors: object           # MotorOutput (zero commands unless armed)
    armed: bool
    measurement_stamp: float  # stamp of the pose the step used (None before the first)


class ControlLoop:
    """State and decisions of the controller node."""

    def __init__(self, setup):
        self.setup = setup
        self.controller = AttitudeController(setup.config)
        self.controller.set_setpoint(setup.setpoint)
        self.pose = Stream('pose', setup.values['pose_timeout'])
        self.rate = Stream('angular velocity', setup.values['imu_timeout'])
        self.supervisor = Supervisor([self.pose, self.rate])
        self.R = None
        self.Omega = None
        self.setpoint_note = None       # last set-point refusal, for diagnostics
        self._schedule_index = -1

    # --- inputs ------------------------------------------------------------------------------
    def offer_pose(self, q, stamp, receipt):
        """A motion-capture attitude (x, y, z, w); None if accepted, else why it was refused."""
        problem = self.pose.offer(stamp, receipt, quaternion_problem(q))
        if problem is None:
            self.R = so3.quat_to_rot(q)
        return problem

    def offer_angular_velocity(self, w, stamp, receipt):
        """A body angular velocity (rad/s); None if accepted, else why it was refused."""
        problem = self.rate.offer(
            stamp, receipt, angular_velocity_problem(w, self.setup.values['max_angular_velocity']))
        if problem is None:
            self.Omega = np.array(w, dtype=float)
        return problem

    def request_setpoint(self, q):
        """A new desired attitude; None if adopted, else why it was refused (old one stays)."""
        problem = quaternion_problem(q)
        if problem is None:
            try:
                self.controller.set_setpoint(so3.quat_to_rot(q))
            except SetpointRejected as e:
                problem = str(e)
        self.setpoint_note = None if problem is None else 'setpoint rejected: ' + problem
        return problem

    # --- commands ----------------------------------------------------------------------------
    def arm(self, now, extra_problem=None):
        """Arm unless an input is stale or extra_problem (a sentence from the caller) says no."""
        result = self.supervisor.arm(now, extra_problem)
        if result.ok:
            self._schedule_index = -1
        return result

    def disarm(self, reason='disarm requested'):
        return self.supervisor.disarm(reason)

    def reset_adaptation(self):
        self.controller.reset_adaptation()

    def reconfigure(self, setup, setpoint_changed=False, schedule_changed=False):
        """Adopt a new setup (validated by params.controller_setup); None, or why not.

        The set point parameter is applied only when it changed, so that a gain change does not
        undo a set point that came in on the topic."""
        try:
            self.controller.reconfigure(setup.config)
        except SetpointRejected as e:
            return str(e)
        self.setup = setup
        self.pose.timeout = setup.values['pose_timeout']
        self.rate.timeout = setup.values['imu_timeout']
        if setpoint_changed:
            self.controller.set_setpoint(setup.setpoint)
        if schedule_changed:
            self._schedule_index = -1
        return None

    # --- the control tick --------------------------------------------------------------------
    def tick(self, now, dt):
        """One control step at time now (the node's clock); dt is the control period."""
        armed = self.supervisor.check(now)
        schedule = self.setup.schedule
        if armed and len(schedule):
            i = schedule.index_at(now - self.supervisor.armed_since)
            if i != self._schedule_index and i >= 0:
                self.controller.set_setpoint(schedule.rotations[i])   # checked at configuration
                self._schedule_index = i
        if self.R is None or self.Omega is None:
            motors = self.setup.mixer.mix(np.zeros(3), armed=False)
            return Tick(None, motors, armed, None)
        out = self.controller.step(self.R, self.Omega, dt, adapt=armed)
        motors = self.setup.mixer.mix(out.u, armed=armed)
        return Tick(out, motors, armed, self.pose.last_stamp)
