"""Running a node: events executor, clean Ctrl-C, exit code 2 for bad parameters."""
import signal

import rclpy
from rclpy.signals import SignalHandlerOptions

from geoctl_ros.params import ConfigError


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def spin(node_class, name, args=None):
    """Create and spin node_class; returns the process exit code.

    rclpy's own signal handler is off, so that after Ctrl-C (or SIGTERM turned into
    KeyboardInterrupt by the caller) the node can still publish its last words (``on_shutdown``,
    e.g. zero motor commands) before the context goes down.
    """
    signal.signal(signal.SIGTERM, _interrupt)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = node_class()
    except ConfigError as e:
        rclpy.logging.get_logger(name).fatal(str(e))
        rclpy.try_shutdown()
        return 2
    try:
        from rclpy.experimental import EventsExecutor
        executor = EventsExecutor()
    except ImportError:      # pragma: no cover - rclpy before 7.1.4
        executor = rclpy.executors.SingleThreadedExecutor()
    executor.add_node(node)
    try:
        # spin_once in a loop: this rclpy's EventsExecutor.spin() was seen to busy-loop here
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except KeyboardInterrupt:
        pass
    finally:
        hook = getattr(node, 'on_shutdown', None)
        if hook is not None:
            hook()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
