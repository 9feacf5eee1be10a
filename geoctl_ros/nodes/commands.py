"""The operator's commands to a running controller, through its own services:

    ros2 run geoctl_ros setpoint --yaw-deg 0 [--pitch-deg 0] [--roll-deg 0]
    ros2 run geoctl_ros setpoint --quaternion X Y Z W
    ros2 run geoctl_ros setpoint --hold
    ros2 run geoctl_ros stop

``setpoint`` sets the controller's ``setpoint`` parameter (its ``set_parameters`` service: the
set point is checked as the controller checks every set point, and flown at once if it is
taken, armed; disarmed, an arming with ``arming_setpoint`` hold replaces it with the hold), or
with --hold calls ``~/hold`` (fly the attitude measured now). The angles are the
package's world (ENU at the motion-capture origin, docs/frames.md) and body (FLU): yaw about up
from the world's x axis, then pitch, then roll (z-y-x, as ``marker_rotation_deg``); an angle not
given is 0. ``stop`` disarms (``~/arm`` false): the rotors stop at once.

Each prints ``accepted: ...`` or ``refused: <reason>``. Exit code 0 when accepted, 1 when
refused, 2 for bad arguments, 3 when the controller does not answer within --wait seconds.
"""
import argparse
import math
import sys

from rcl_interfaces.srv import SetParameters
import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.utilities import remove_ros_args
from std_srvs.srv import SetBool, Trigger

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.sensors.frames import rpy_matrix
from geoctl_ros.nodes.conversions import refusal_reason
from geoctl_ros.params import SETPOINT

ACCEPTED, REFUSED, BAD_ARGUMENTS, NO_ANSWER = 0, 1, 2, 3


def setpoint_quaternion(yaw_deg: float, pitch_deg: float, roll_deg: float) -> list:
    """The set point (x, y, z, w) of yaw, pitch and roll (deg, z-y-x) in the package's world."""
    return [float(v) for v in so3.rot_to_quat(rpy_matrix((roll_deg, pitch_deg, yaw_deg)))]


def _call(node, service_type, name, request, wait):
    """Call the controller's service name; its response, or None without an answer in wait s."""
    client = node.create_client(service_type, name)
    if not client.wait_for_service(timeout_sec=wait):
        return None
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=wait)
    return future.result()


def _run(prog, description, argv, build, call, problem=lambda args: None):
    """Parse argv (ROS arguments removed) with build(parser) (problem(args): why they cannot
    be used, or None), then call(node, args, service prefix) -> (accepted, text) or None (no
    answer); print the answer, return the exit code.
    """
    argv = sys.argv if argv is None else argv
    parser = argparse.ArgumentParser(
        prog=prog, description=description + ' Prints "accepted: ..." or "refused: <reason>"; '
        'exit code 0 accepted, 1 refused, 2 bad arguments, 3 no answer (docs/interface.md, '
        '"Set points and the stop").')
    parser.add_argument('--controller', default='controller',
                        help="the controller node's name (controller)")
    parser.add_argument('--wait', type=float, default=10.0,
                        help='seconds to wait for the controller to answer (10)')
    build(parser)
    args = parser.parse_args(remove_ros_args(argv)[1:])
    if not math.isfinite(args.wait) or args.wait <= 0.0:
        parser.error('--wait must be a positive number of seconds')
    why = problem(args)
    if why:
        parser.error(why)           # (exit code 2: BAD_ARGUMENTS)
    rclpy.init(args=argv)
    node = Node('geoctl_' + prog)
    try:
        prefix = '/' + args.controller.strip('/')
        answer = call(node, args, prefix)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    if answer is None:
        print('%s: no answer from %s within %g s (is the controller running, in this '
              'ROS_DOMAIN_ID?)' % (prog, prefix, args.wait), file=sys.stderr)
        return NO_ANSWER
    accepted, text = answer
    print(('accepted: ' if accepted else 'refused: ') + text)
    return ACCEPTED if accepted else REFUSED


def _setpoint_arguments(parser):
    which = parser.add_mutually_exclusive_group()
    which.add_argument('--quaternion', type=float, nargs=4, metavar=('X', 'Y', 'Z', 'W'),
                       help='the set point as a unit quaternion (x, y, z, w)')
    which.add_argument('--hold', action='store_true',
                       help='hold the attitude measured now (lifted off the stops)')
    for name, what in (('yaw', 'about up, from the world x axis towards y'),
                       ('pitch', 'then about the body y axis'),
                       ('roll', 'then about the body x axis')):
        parser.add_argument('--%s-deg' % name, type=float, default=None,
                            help='%s (deg), %s; 0 if not given' % (name, what))


def _angles(args):
    """(yaw, pitch, roll) in degrees, or None if none is given."""
    given = (args.yaw_deg, args.pitch_deg, args.roll_deg)
    if all(a is None for a in given):
        return None
    return tuple(0.0 if a is None else a for a in given)


def _send_setpoint(node, args, prefix):
    if args.hold:
        r = _call(node, Trigger, prefix + '/hold', Trigger.Request(), args.wait)
        return None if r is None else (r.success, r.message)
    if args.quaternion is not None:
        q, shown = [float(v) for v in args.quaternion], 'the quaternion'
    else:
        yaw, pitch, roll = _angles(args)
        q = setpoint_quaternion(yaw, pitch, roll)
        shown = 'yaw %g, pitch %g, roll %g deg' % (yaw, pitch, roll)
    request = SetParameters.Request(parameters=[Parameter(SETPOINT, value=q).to_parameter_msg()])
    r = _call(node, SetParameters, prefix + '/set_parameters', request, args.wait)
    if r is None:
        return None
    result = r.results[0] if r.results else None
    if result is None or not result.successful:
        return False, refusal_reason(result.reason if result is not None else '')
    return True, 'set point [%s] (x, y, z, w; %s)' % (', '.join('%.4f' % v for v in q), shown)


def _setpoint_problem(args):
    """Why these arguments name no one set point, or None."""
    if sum([args.quaternion is not None, args.hold, _angles(args) is not None]) != 1:
        return 'give one of --yaw-deg/--pitch-deg/--roll-deg, --quaternion or --hold'
    numbers = list(_angles(args) or ()) + list(args.quaternion or ())
    if not all(math.isfinite(v) for v in numbers):
        return 'the angles and the quaternion must be finite numbers'
    return None


def setpoint(argv=None):
    """``setpoint``: send the controller a set point (or --hold); see the module."""
    return _run('setpoint', "Send the controller a set point in the package's world (ENU), or "
                '--hold the attitude now.', argv, _setpoint_arguments, _send_setpoint,
                _setpoint_problem)


def stop(argv=None):
    """``stop``: disarm the controller (the rotors stop at once)."""
    def call(node, args, prefix):
        r = _call(node, SetBool, prefix + '/arm', SetBool.Request(data=False), args.wait)
        return None if r is None else (r.success, r.message)

    return _run('stop', 'Disarm the controller: the rotors stop.', argv, lambda parser: None,
                call)


if __name__ == '__main__':      # python -m geoctl_ros.nodes.commands setpoint|stop ARGS
    command = {'setpoint': setpoint, 'stop': stop}.get(sys.argv[1] if len(sys.argv) > 1 else '')
    if command is None:
        sys.exit('usage: python -m geoctl_ros.nodes.commands setpoint|stop [ARGS]')
    sys.exit(command(sys.argv[1:]))
