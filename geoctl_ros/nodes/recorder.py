"""The flight recorder: ``ros2 run geoctl_ros record`` writes the package's topics to a rosbag2
bag (MCAP by default, or sqlite3) as ``ros2 bag record`` would, in a process of its own.

Its topics are chosen by their package names (``record.topics``) and remapped as any node's:
given the controller's remaps (``-r pose:=/vicon/hexrotor/pose -r imu:=/vn100/imu``), it records
the drivers' raw topics under their real names, and writes which package name each stands for
into the bag (``/record/topic_names``), so that ``report`` reads them as ``/pose`` and ``/imu``.

Messages are recorded as they arrive (the bytes rclpy received, stamped with the receipt time on
this node's clock) and written by geoctl_ros.records.bag on a thread of its own, so the disk never
holds up a callback. The controller's cone and sensor parameters are asked for once it is up and
written into the bag as a message of its own (``/record/controller_parameters``), so that
``report`` can draw the cones, from a bag cut short too.
"""
import datetime
import importlib
import os
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from std_msgs.msg import String
import yaml

from geoctl_ros.nodes import qos, ros_params
from geoctl_ros.nodes.controller_params import ControllerParameters
from geoctl_ros.nodes.runtime import spin
from geoctl_ros.params import RECORD, ConfigError, settings
from geoctl_ros.params.topics import BY_NAME, CONTROLLER_PARAMETERS, RECORDED_NAMES
from geoctl_ros.records import bag, health
from geoctl_ros.records.health import RecordFigures

STATUS_NAME = health.NAME
DEPTH = 50          # a burst of this many per topic waits for the callback, none is lost


def _qos(topic):
    """What the subscription asks: the publisher's reliability and durability, a deep queue."""
    return QoSProfile(
        depth=DEPTH,
        reliability=(ReliabilityPolicy.RELIABLE if topic.reliable
                     else ReliabilityPolicy.BEST_EFFORT),
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if topic.transient_local
                    else DurabilityPolicy.VOLATILE))


def default_path(now=None):
    """records/flight_<UTC date and time> under the working directory."""
    now = now or datetime.datetime.now(datetime.timezone.utc)
    return os.path.join('records', now.strftime('flight_%Y%m%d_%H%M%S'))


class Recorder(Node):
    def __init__(self, **kwargs):
        super().__init__('record', **kwargs)
        cfg = settings(ros_params.load(self, RECORD), 'record.')
        self.path = cfg.path or default_path()
        # each topic under its real name: the package's, or where this node's remaps send it
        chosen = [BY_NAME[name] for name in cfg.topics]
        topics = [t._replace(name=self.resolve_topic_name(t.name)) for t in chosen]
        renamed = {c.name: t.name for c, t in zip(chosen, topics) if c.name != t.name}
        parent = os.path.dirname(os.path.abspath(self.path))
        os.makedirs(parent, exist_ok=True)
        try:
            self.writer = bag.BagWriter(self.path, topics, cfg.storage)
        except ValueError as e:         # the folder exists, or cannot be made: say so, exit 2
            raise ConfigError([('record.path', str(e))]) from None
        clock = self.get_clock()
        self.writer.put(RECORDED_NAMES.name, clock.now().nanoseconds,
                        serialize_message(String(data=yaml.safe_dump(renamed))))
        self._silent = {t.name for t in topics}           # no message yet
        for topic in topics:
            def on_message(data, name=topic.name):
                self.writer.put(name, clock.now().nanoseconds, data)
                if name in self._silent:
                    self._silent.discard(name)
                    self.get_logger().info('first message on %s' % name)
            self.create_subscription(self._msg_class(topic.type), topic.name, on_message,
                                     _qos(topic), raw=True)
        ControllerParameters(self, cfg.controller, self._store_controller_parameters)
        self._error_said = False
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', qos.EVENT)
        self.create_timer(1.0, self._check_writer)
        self.get_logger().info('recording %d topics to %s (%s)%s' % (
            len(topics), self.path, cfg.storage, ''.join(
                ', %s as %s' % pair for pair in renamed.items())))

    @staticmethod
    def _msg_class(type_name):
        package, _, name = type_name.split('/')
        return getattr(importlib.import_module(package + '.msg'), name)

    def _store_controller_parameters(self, values):
        self.writer.put(CONTROLLER_PARAMETERS.name, self.get_clock().now().nanoseconds,
                        serialize_message(String(data=yaml.safe_dump(values))))
        self.get_logger().info("stored the controller's %d cone and sensor parameters"
                               % len(values))

    def _check_writer(self, publish=True):
        """Say at once when the bag stopped (a full disk): what was written stays readable. Its
        state goes to /diagnostics every second: ERROR once the bag stopped, else OK.
        """
        w = self.writer
        if w.error is not None and not self._error_said:
            self._error_said = True
            self.get_logger().error('the bag stopped: %s (what was written up to then stays '
                                    'readable: report reads it)' % w.error)
        if not publish:
            return
        if w.error is not None:
            level, text = DiagnosticStatus.ERROR, 'the bag stopped: %s' % w.error
        else:
            level, text = DiagnosticStatus.OK, 'recording to %s' % self.path
        status = DiagnosticStatus(level=level, name=STATUS_NAME, hardware_id='record',
                                  message=text, values=[
                                      KeyValue(key=k, value=v) for k, v in health.to_values(
                                          RecordFigures(sum(w.counts.values()), w.dropped))])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(msg)

    def on_shutdown(self):
        self.writer.close()
        counts = ', '.join('%s %d' % (k, n) for k, n in self.writer.counts.items() if n)
        self.get_logger().info('wrote %s: %s%s' % (self.path, counts or 'no messages', (
            '; %d dropped' % self.writer.dropped) if self.writer.dropped else ''))
        self._check_writer(publish=False)


def main():
    sys.exit(spin(Recorder, 'record'))


if __name__ == '__main__':
    main()
