"""The ESC node: ``ros2 run geoctl_ros esc_i2c`` writes ``motor_commands`` to the BL-Ctrl ESCs on
I2C (``esc.*`` and ``motor_test.*`` in docs/parameters.md; docs/esc.md, "ESCs on I2C").

A thin shell over ``geoctl_ros.esc.driver.EscDriver``, which decides everything: zero at start,
on shutdown and on SIGINT/SIGTERM; the watchdog (commands older than ``esc.timeout``, malformed,
or none yet give zero); retries; the motor test's refusals. The bus belongs to one thread of its
own: it writes every ESC when a command arrives and at least ``esc.rate_hz`` times a second, and
reads one ESC's telemetry ``esc.telemetry_rate_hz`` times a second, so nothing on the bus waits
for the executor and the executor never waits for the bus. The subscription only hands the
command over and wakes that thread.

Publishes ``esc/telemetry`` (Float64MultiArray: current A, state byte, temperature deg C per
rotor; NaN where not read) and ``/diagnostics`` (``geoctl_ros: esc_i2c``, every 0.5 s). Services
``~/motor_test`` (std_srvs/Trigger: rotor ``motor_test.rotor`` at ``motor_test.command`` for
``motor_test.duration``; refused while the controller is armed) and ``~/motor_test_stop``.
"""
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from std_srvs.srv import Trigger

from geoctl_ros.core.telemetry.scheduling import scheduling
from geoctl_ros.esc import health
from geoctl_ros.esc.bus import I2cBus
from geoctl_ros.esc.driver import EscDriver, EscStartError
from geoctl_ros.esc.virtual import VirtualEscBus
from geoctl_ros.nodes import qos, ros_params
from geoctl_ros.nodes.conversions import (
    armed_state_of,
    commands_of,
    esc_health_msg,
    session_of,
)
from geoctl_ros.nodes.runtime import RefusalLog, spin
from geoctl_ros.params import ESC, ESC_LIVE, ConfigError, change_problem, resolve
from geoctl_ros.params.esc import esc_setup

REPORT_PERIOD = 0.5             # s between diagnostics and telemetry messages


class EscNode(Node):
    def __init__(self, **kwargs):
        super().__init__('esc_i2c', **kwargs)
        values = ros_params.load(self, ESC)
        self.setup = setup = esc_setup(values)
        config = setup.driver
        path = setup.virtual_bus
        try:
            bus = (VirtualEscBus(path, config.addresses) if path
                   else I2cBus(setup.bus))
        except (OSError, ValueError) as e:
            raise ConfigError([('esc.virtual_bus' if path else 'esc.bus',
                                'cannot open the bus: %s (docs/esc.md, "ESCs on I2C")'
                                % e)]) from None
        self.bus = bus
        self.driver = EscDriver(config, bus)
        try:
            self.driver.start()
        except EscStartError as e:
            bus.close()
            raise ConfigError([('esc.addresses', str(e))]) from None
        self.refusals = RefusalLog(self.get_logger())
        self._report_base = (0, 0)
        self.scheduling = scheduling()      # (the realtime prefix's class: read once)
        self._stop = threading.Event()
        self._wake = threading.Event()
        self.create_subscription(JointState, 'motor_commands', self._on_commands,
                                 qos.COMMAND)
        self.create_subscription(DiagnosticStatus, '%s/armed' % setup.controller,
                                 self._on_armed, qos.LATCHED)
        self.pub_telemetry = self.create_publisher(Float64MultiArray, 'esc/telemetry',
                                                   qos.TELEMETRY)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', qos.EVENT)
        self.pub_health = self.create_publisher(DiagnosticStatus, 'esc_health', qos.COMMAND)
        self.create_service(Trigger, '~/motor_test', self._on_motor_test)
        self.create_service(Trigger, '~/motor_test_stop', self._on_motor_test_stop)
        ros_params.watch(self, ESC, self._validate, self._on_params)
        self.create_timer(REPORT_PERIOD, self._report)
        self._thread = threading.Thread(target=self._bus_loop, name='esc bus', daemon=True)
        self._thread.start()
        missing = sorted(i + 1 for i in self.driver.missing)
        self.get_logger().info('esc_i2c: %d ESCs on %s (%s), %d-bit set points, timeout %g s%s'
                               % (len(config.addresses), bus.name,
                                  ' '.join('0x%02x' % a for a in config.addresses),
                                  config.resolution, config.timeout,
                                  ', rotors %s missing (ignored)' % missing if missing else ''))

    # --- the bus thread ---------------------------------------------------------------------
    def _bus_loop(self):
        period = 1.0 / self.setup.rate_hz
        rate = self.setup.telemetry_rate_hz
        next_read = time.monotonic()
        while not self._stop.is_set():
            self._wake.wait(period)
            self._wake.clear()
            if self._stop.is_set():
                break
            self.driver.write()
            now = time.monotonic()
            if rate > 0.0 and now >= next_read:
                self.driver.read_next()
                next_read = max(next_read + 1.0 / rate, now)

    def on_shutdown(self):
        """Zero to every ESC (the runtime calls this on SIGINT/SIGTERM and at exit)."""
        self._stop.set()
        self._wake.set()
        self._thread.join(1.0)
        failed = self.driver.stop()
        if failed:
            self.get_logger().error('zero not written to %s' % ' '.join('0x%02x' % a
                                                                      for a in failed))
        else:
            self.get_logger().info('esc_i2c: zero written to every ESC')
        self.bus.close()

    # --- callbacks ---------------------------------------------------------------------------
    def _on_commands(self, msg):
        foreign = self.driver.foreign
        problem = self.driver.offer(commands_of(msg), session=session_of(msg))
        self._wake.set()
        if problem and self.driver.foreign > foreign:
            self.refusals.warn("motor_commands refused (the controller's stay in force): ",
                               problem)
        elif problem:
            self.refusals.warn('motor_commands refused (every ESC gets zero): ', problem)

    def _on_armed(self, msg):
        state = armed_state_of(msg)
        if state is None:
            self.refusals.warn('armed state refused: ',
                               'not the key-values armed (true or false) and session')
            return
        if state.armed and not self.driver.armed and self.driver.abort_test():
            self.get_logger().warning('motor test ended: the controller armed')
        if state.armed != self.driver.armed:
            self.get_logger().info('controller %s (session %d): ESC set points %s'
                                   % ('armed' if state.armed else 'disarmed', state.session,
                                      'follow its commands' if state.armed else 'zero'))
        self.driver.follow(state.armed, state.session)
        self._wake.set()

    @property
    def armed(self):
        return self.driver.armed

    def _validate(self, values, changed):
        """A run-time change: only of what this node applies live (``ESC_LIVE``)."""
        problem = change_problem(changed, ESC_LIVE, 'at start (restart esc_i2c)')
        if problem:
            raise ConfigError([('esc_i2c', problem)])
        return resolve(ESC, values)

    def _on_params(self, values, changed):
        self.setup = esc_setup(values)

    def _on_motor_test(self, request, response):
        test = self.setup.motor_test
        rotor, command, duration = test.rotor, test.command, test.duration
        why = self.driver.start_test(rotor, command, duration, self.armed)
        response.success = why is None
        response.message = why or ('rotor %d at %g for %g s' % (rotor, command, duration))
        self._wake.set()
        log = self.get_logger().info if why is None else self.get_logger().warning
        log('motor test: ' + response.message)
        return response

    def _on_motor_test_stop(self, request, response):
        response.success = self.driver.abort_test()
        response.message = 'stopped' if response.success else 'no motor test was running'
        self._wake.set()
        return response

    def _report(self):
        d = self.driver
        now = time.monotonic()
        warn, error = self.setup.temperature_warn, self.setup.temperature_error
        r = health.report(d, now, warn, error, *self._report_base, scheduling=self.scheduling)
        self.pub_health.publish(esc_health_msg(
            d.config.command_max, health.esc_health(d, now, error), self.bus.name))
        self._report_base = (r.figures.i2c_errors, r.figures.refused)
        d.latency.reset()
        status = DiagnosticStatus(level=bytes([r.level]), name=health.NAME,
                                  hardware_id=self.bus.name, message=r.message,
                                  values=[KeyValue(key=k, value=v)
                                          for k, v in health.to_values(r.figures)])
        out = DiagnosticArray(status=[status])
        out.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(out)
        msg = Float64MultiArray()
        msg.layout.dim = [MultiArrayDimension(label='rotor', size=d.n, stride=3 * d.n),
                          MultiArrayDimension(label='current_A state temperature_C', size=3,
                                              stride=3)]
        nan = float('nan')
        for tel in d.telemetry:
            msg.data.extend([nan, nan, nan] if tel is None else
                            [tel.current, float(tel.state), tel.temperature])
        self.pub_telemetry.publish(msg)


def main():
    sys.exit(spin(EscNode, 'esc_i2c'))


if __name__ == '__main__':
    main()
