"""The live 3D view: ``ros2 run geoctl_ros view`` publishes ``view/markers``
(visualization_msgs/MarkerArray, best effort, in the world frame) at ``view.rate_hz`` for RViz2
(``config/rviz/geoctl.rviz``) or Foxglove: each cone as a surface at its half-angle (red while the
sensor is within ``view.warning_deg`` of it), the sensor axis as an arrow with a trail of where it
pointed, the body axes, and the set point's sensor direction. The geometry is
``geoctl_ros.core.telemetry.view``'s; the cones are the controller's, asked for over its parameter
services.
"""
import sys

from geometry_msgs.msg import Point, QuaternionStamped
import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node
from std_msgs.msg import ColorRGBA, Float64MultiArray
from visualization_msgs.msg import Marker, MarkerArray

from geoctl_ros.core.supervisor.safety import attitude_of
from geoctl_ros.core.telemetry.view import Trail, cone_triangles, in_warning
from geoctl_ros.nodes import qos, ros_params
from geoctl_ros.nodes.controller_params import ControllerParameters
from geoctl_ros.nodes.runtime import RefusalLog, spin
from geoctl_ros.params import CONTROLLER, VIEW, cone_set, resolve, settings
from geoctl_ros.records.fields import quaternion

CONE_COLOUR = ColorRGBA(r=1.0, g=0.6, b=0.0, a=0.35)
WARNING_COLOUR = ColorRGBA(r=1.0, g=0.0, b=0.0, a=0.7)
SENSOR_COLOUR = ColorRGBA(r=0.1, g=0.3, b=1.0, a=1.0)
TRAIL_COLOUR = ColorRGBA(r=0.4, g=0.6, b=1.0, a=0.8)
SETPOINT_COLOUR = ColorRGBA(r=0.0, g=0.8, b=0.0, a=1.0)
AXIS_COLOURS = (ColorRGBA(r=1.0, a=1.0), ColorRGBA(g=1.0, a=1.0), ColorRGBA(b=1.0, a=1.0))


def _points(rows):
    return [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in rows]


class View(Node):
    def __init__(self, **kwargs):
        super().__init__('view', **kwargs)
        cfg = settings(ros_params.load(self, VIEW), 'view.')
        self.frame = cfg.world_frame_id
        self.warning_deg = cfg.warning_deg
        self.lifetime = Duration(seconds=3.0 / cfg.rate_hz).to_msg()
        self.trail = Trail(max(2, int(round(cfg.trail_s * cfg.rate_hz))))
        self.cones = None
        self.R = self.R_d = None
        self.margins = None
        self.refusals = RefusalLog(self.get_logger())
        self.create_subscription(QuaternionStamped, 'attitude', lambda m: self._take_attitude(
            'R', 'attitude', quaternion(m.quaternion)), qos.TELEMETRY)
        self.create_subscription(QuaternionStamped, 'active_setpoint',
                                 lambda m: self._take_attitude('R_d', 'active_setpoint',
                                                               quaternion(m.quaternion)),
                                 qos.LATCHED)
        self.create_subscription(Float64MultiArray, 'cone_margins', self._on_margins,
                                 qos.TELEMETRY)
        self.pub = self.create_publisher(MarkerArray, 'view/markers', qos.TELEMETRY)
        ControllerParameters(self, cfg.controller, self._on_controller)
        self.create_timer(1.0 / cfg.rate_hz, self._publish)
        self.get_logger().info('view/markers at %g Hz in frame %s' % (cfg.rate_hz, self.frame))

    def _take_attitude(self, field, topic, q):
        """A quaternion drawn as an attitude; a zero, non-unit or NaN one is refused and logged
        (a zero one ended the view).
        """
        R, problem = attitude_of(q)
        if problem:
            self.refusals.warn('%s refused: ' % topic, problem)
            return
        setattr(self, field, R)

    def _on_margins(self, msg):
        margins = np.array(msg.data, dtype=float)
        if not np.isfinite(margins).all():
            self.refusals.warn('cone_margins refused: ', 'not finite')
            return
        self.margins = margins

    def _on_controller(self, values):
        self.cones = cone_set(resolve(CONTROLLER, values))
        self.get_logger().info('drawing %d cone(s)' % len(self.cones))

    def _marker(self, ns, i, kind, colour, points=(), scale=(1.0, 1.0, 1.0)):
        m = Marker(ns=ns, id=i, type=kind, action=Marker.ADD, color=colour,
                   lifetime=self.lifetime, frame_locked=False)
        m.header.frame_id = self.frame
        m.header.stamp = self.get_clock().now().to_msg()
        m.pose.orientation.w = 1.0
        m.scale.x, m.scale.y, m.scale.z = scale
        m.points = _points(points)
        return m

    def markers(self):
        """The MarkerArray of the present state (what is not known yet is left out)."""
        out = []
        if self.cones is not None:
            warn = (in_warning(self.margins, self.warning_deg)
                    if self.margins is not None and len(self.margins) == len(self.cones)
                    else np.zeros(len(self.cones), bool))
            for i, (axis, theta) in enumerate(zip(self.cones.V, self.cones.theta)):
                out.append(self._marker('cones', i, Marker.TRIANGLE_LIST,
                                        WARNING_COLOUR if warn[i] else CONE_COLOUR,
                                        cone_triangles(axis, theta)))
        arrow = (0.02, 0.05, 0.08)
        if self.R is not None:
            r = self.cones.r if self.cones is not None else np.array([1.0, 0.0, 0.0])
            sensor = self.R @ r
            self.trail.add(sensor)
            out.append(self._marker('sensor', 0, Marker.ARROW, SENSOR_COLOUR,
                                    [(0.0, 0.0, 0.0), sensor], arrow))
            out.append(self._marker('trail', 0, Marker.LINE_STRIP, TRAIL_COLOUR,
                                    self.trail.points(), (0.01, 0.0, 0.0)))
            for k in range(3):
                out.append(self._marker('body', k, Marker.ARROW, AXIS_COLOURS[k],
                                        [(0.0, 0.0, 0.0), 0.5 * self.R[:, k]], arrow))
            if self.R_d is not None:
                out.append(self._marker('setpoint', 0, Marker.ARROW, SETPOINT_COLOUR,
                                        [(0.0, 0.0, 0.0), self.R_d @ r], arrow))
        return MarkerArray(markers=out)

    def _publish(self):
        self.pub.publish(self.markers())


def main():
    sys.exit(spin(View, 'view'))


if __name__ == '__main__':
    main()
