"""The simulation node: ``ros2 run geoctl_ros sim --ros-args --params-file FILE``.

A thin shell over ``geoctl_ros.sim.testbed.TestbedSim``: integrates the testbed at
``integration_rate_hz`` from the latest ``motor_commands`` (normalised, as the controller publishes
them; with ``actuation: torque``, from the torque of the latest ``control_wrench``), and publishes
``pose`` (motion capture) and ``imu`` (angular velocity and specific force) with the configured
noise, in the conventions it is given (``pose_world_frame``, ``body_frame``,
``marker_rotation_deg``, ``imu_rotation_deg``: the sources it emulates; ``core.sensors.frames``),
the true state on
``sim/true_pose``, and ``/clock`` when ``publish_clock`` is set. Simulated time follows the wall
clock times ``real_time_factor``: one timer, at the faster of the two sensor rates, integrates as
many steps as are due and publishes what is due.

With ``esc.virtual_bus`` set the sim is the ESCs instead: it reads each one's set point from that
virtual I2C bus (written by ``esc_i2c`` through the real encoding) and answers their telemetry.

Commands (or bus writes) older than ``command_timeout`` stop the motors (as the ESCs do when the
I2C bus goes quiet; ``geoctl_ros.sim.testbed.EscWatchdog``, which does not count the sim's own
stalls); a
malformed command message (wrong length, not finite, outside [0, 1]) is refused with a warning and
the previous one stays.
"""
import sys
import time

from geometry_msgs.msg import PoseStamped, WrenchStamped
import numpy as np
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import Imu, JointState

from geoctl_ros.core.actuation.esc_wire import motor_commands_problem
from geoctl_ros.core.geometry import so3
from geoctl_ros.esc.protocol import current_raw, decode
from geoctl_ros.esc.virtual import VirtualEscBus
from geoctl_ros.nodes import qos, ros_params
from geoctl_ros.nodes.conversions import commands_of, set_quaternion, set_vector, time_msg
from geoctl_ros.nodes.runtime import RefusalLog, spin
from geoctl_ros.params import SIM, ConfigError, settings
from geoctl_ros.params.build import emulated_imu
from geoctl_ros.params.esc import virtual_escs
from geoctl_ros.records.fields import vector
from geoctl_ros.sim.testbed import EscWatchdog, testbed_sim

LATE = 0.05     # s behind real time before the sim warns


class SimNode(Node):
    def __init__(self, **kwargs):
        super().__init__('sim', **kwargs)
        values = ros_params.load(self, SIM)
        self.sim = testbed_sim(values)
        cfg = settings(values)
        rotors = self.sim.actuator              # None with torque actuation
        self.n_rotors = len(rotors.thrusts) if rotors else 0
        self.command_max = rotors.curve.command_max if rotors else 0
        self.h = 1.0 / cfg.integration_rate_hz
        self.rtf = cfg.real_time_factor
        self.command_timeout = cfg.command_timeout
        self.esc = EscWatchdog(self.command_timeout, LATE)
        self.publish_clock = cfg.publish_clock
        self.commands = np.zeros(self.n_rotors)
        self.torque = np.zeros(3)
        self.ever_commanded = False
        self.commands_fresh = False
        # sim time 0 is the first step, not construction: on a loaded machine creating the
        # publishers can take seconds, and the sim would start that far behind real time
        self.wall0 = self.ros0 = None
        self.pose_period = 1.0 / cfg.pose_rate_hz
        self.imu_period = 1.0 / cfg.imu_rate_hz
        self.next_pose = self.next_imu = 0.0
        # the sources it emulates: their conventions, and the IMU's place and accelerometer
        imu = emulated_imu(values)
        self.frames, self.imu_position = imu.frames, imu.position
        self.force_noise, self.gravity = imu.force_noise, imu.gravity
        self._last_imu = None                     # (t, Omega) at the last imu sample

        self.esc_bus = None
        self.refusals = RefusalLog(self.get_logger())
        escs = virtual_escs(values)
        if self.n_rotors and escs is not None:      # the ESCs on a virtual I2C bus
            addresses = escs.addresses
            if len(addresses) != self.n_rotors:
                raise ConfigError([('esc.addresses', 'expected %d (one per rotor), got %d'
                                    % (self.n_rotors, len(addresses)))])
            try:
                self.esc_bus = VirtualEscBus(escs.path, addresses)
            except (OSError, ValueError) as e:
                raise ConfigError([('esc.virtual_bus', str(e))]) from None
            self.esc_bus.power(True)
            self._bus_writes = -1.0
        elif self.n_rotors:
            self.create_subscription(JointState, 'motor_commands', self._on_commands,
                                     qos.COMMAND)
        else:                          # ideal actuation: the controller's moment itself
            self.create_subscription(WrenchStamped, 'control_wrench', self._on_wrench,
                                     qos.COMMAND)
        self.pub_pose = self.create_publisher(PoseStamped, 'pose', qos.SENSOR)
        self.pub_imu = self.create_publisher(Imu, 'imu', qos.SENSOR)
        self.pub_true = self.create_publisher(PoseStamped, 'sim/true_pose', qos.TELEMETRY)
        self.pub_clock = (self.create_publisher(ClockMsg, '/clock', qos.EVENT)
                          if self.publish_clock else None)
        self.pose_msg, self.true_msg, self.imu_msg = PoseStamped(), PoseStamped(), Imu()
        self.pose_msg.header.frame_id = self.true_msg.header.frame_id = cfg.world_frame_id
        self.imu_msg.header.frame_id = cfg.frame_id
        self.imu_msg.orientation_covariance[0] = -1.0            # no orientation in this imu
        wall_period = min(self.pose_period, self.imu_period) / self.rtf
        self.create_timer(wall_period, self._on_timer)
        self.get_logger().info('sim ready: %s actuation, %g Hz integration, pose %g Hz, '
                               'imu %g Hz, '
                               'real-time factor %g' % (cfg.actuation, cfg.integration_rate_hz,
                                                         cfg.pose_rate_hz, cfg.imu_rate_hz,
                                                         self.rtf))

    def _on_commands(self, msg):
        values = commands_of(msg)
        problem = motor_commands_problem(values, self.n_rotors)
        if problem:
            self.refusals.warn('motor_commands refused: ', problem)
            return
        data = np.asarray(values, dtype=float)
        self.commands = np.rint(data * self.command_max)
        self.esc.received(time.monotonic())
        self.ever_commanded = True

    def _on_wrench(self, msg):
        torque = np.array(vector(msg.wrench.torque))
        if not np.all(np.isfinite(torque)):
            self.get_logger().warning('control_wrench refused: not finite',
                                      throttle_duration_sec=1.0)
            return
        self.torque = torque
        self.esc.received(time.monotonic())
        self.ever_commanded = True

    def _read_esc_bus(self, now):
        """The set points the ESC node last wrote (the ESCs' view of the bus); telemetry back."""
        bus = self.esc_bus
        written = bus.setpoints()
        latest = max(t for _, t in written)
        if latest > self._bus_writes:
            self._bus_writes = latest
            self.esc.received(now)
            self.ever_commanded = True
        self.commands = np.array([decode(data, self.command_max) * self.command_max
                                  if data else 0.0 for data, _ in written])
        for i, f in enumerate(self.sim.actuator.thrusts):      # a crude ESC: 2 A per newton
            running = self.commands[i] > 0.0 and self.commands_fresh
            bus.answer(i, current_raw(2.0 * f), 255 if running else 250, 35.0)

    def on_shutdown(self):
        if self.esc_bus is not None:
            # the ESCs stay powered a moment: an esc_i2c stopped at the same time (ros2 launch
            # stops every node at once) gets its zeros through before they go
            time.sleep(0.3)
            self.esc_bus.power(False)
            self.esc_bus.close()

    def _stamp(self, t_sim):
        """The capture stamp of the state at sim time t_sim: the ROS clock's time at which real
        time reached it (as a motion-capture system stamps capture time), so a sim that falls
        behind real time publishes honestly old stamps; sim time itself with publish_clock.
        """
        if self.publish_clock:
            return time_msg(t_sim)
        return time_msg(self.ros0 + t_sim / self.rtf)

    def _on_timer(self):
        now = time.monotonic()
        if self.wall0 is None:
            self.wall0 = now
            self.ros0 = self.get_clock().now().nanoseconds * 1e-9   # the ROS clock at wall0
        target = (now - self.wall0) * self.rtf
        plant = self.sim.plant
        behind = (target - plant.t) / self.rtf
        if behind > LATE:       # the process did not get the CPU (or was stopped): say so
            self.get_logger().warning('sim %.0f ms behind real time: its measurements come late'
                                      % (behind * 1e3), throttle_duration_sec=1.0)
        if self.esc_bus is not None:
            self._read_esc_bus(now)
        fresh = self.esc.fresh(now)
        if fresh != self.commands_fresh:
            self.commands_fresh = fresh
            if fresh:
                self.get_logger().info('motor_commands received: motors running')
            elif self.ever_commanded:
                self.get_logger().warning('motor_commands stale (older than %.3f s): motors '
                                          'stopped' % self.command_timeout)
        command = (self.commands if fresh else np.zeros_like(self.commands)) if self.n_rotors \
            else (self.torque if fresh else np.zeros(3))
        steps = 0
        while plant.t + self.h <= target + 1e-12 and steps < 1000:
            self.sim.step(command, self.h)
            steps += 1
        t = plant.t
        if self.pub_clock is not None:
            self.pub_clock.publish(ClockMsg(clock=time_msg(t)))
        if t + 1e-9 >= self.next_pose:
            self.next_pose = t + self.pose_period
            stamp = self._stamp(t)
            self.pose_msg.header.stamp = stamp
            set_quaternion(self.pose_msg.pose.orientation, so3.rot_to_quat(
                self.frames.source_attitude(self.sim.measure_attitude())))
            self.pub_pose.publish(self.pose_msg)
            self.true_msg.header.stamp = stamp
            set_quaternion(self.true_msg.pose.orientation, so3.rot_to_quat(plant.R))
            self.pub_true.publish(self.true_msg)
        if t + 1e-9 >= self.next_imu:
            self.next_imu = t + self.imu_period
            self.imu_msg.header.stamp = self._stamp(t)
            set_vector(self.imu_msg.angular_velocity, self.sim.measure_angular_velocity(
                frames=self.frames))
            set_vector(self.imu_msg.linear_acceleration, self._specific_force(t))
            self.pub_imu.publish(self.imu_msg)

    def _specific_force(self, t):
        """What the emulated accelerometer reads at t: the specific force at imu_position (the
        angular acceleration from the last two samples), in its axes, with its noise.
        """
        plant = self.sim.plant
        last, self._last_imu = self._last_imu, (t, plant.Omega.copy())
        alpha = (np.zeros(3) if last is None or t <= last[0]
                 else (plant.Omega - last[1]) / (t - last[0]))
        f = self.sim.specific_force(self.gravity, self.imu_position, alpha)
        f = self.frames.source_vector(f)
        if self.force_noise > 0.0:
            f = f + self.sim.rng.normal(0.0, self.force_noise, 3)
        return f


def main():
    sys.exit(spin(SimNode, 'sim'))


if __name__ == '__main__':
    main()
