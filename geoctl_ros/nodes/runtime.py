"""Running a node: events executor, clean stop on SIGINT/SIGTERM, exit code 2 for bad
parameters, a WARN line when the realtime prefix could not put it in the real-time class.
"""
import gc
import math
import signal
import sys
import time

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.experimental import EventsExecutor
from rclpy.signals import SignalHandlerOptions

from geoctl_ros.core.telemetry.scheduling import scheduling, scheduling_problem
from geoctl_ros.params import ConfigError


class _StopFlag:
    def __init__(self):
        self.raised = False

    def __call__(self, signum, frame):
        self.raised = True


def make_executor():
    """The executor every process of this package spins its nodes with: rclpy's EventsExecutor
    (Jazzy's rclpy 7.1 has it), which serves a callback with less latency and CPU than the
    single-threaded executor's wait sets.
    """
    return EventsExecutor()


def spin(node_class, name, args=None):
    """Create and spin node_class until SIGINT or SIGTERM; returns the process exit code.

    The signals only set a flag (rclpy's own handler is off), so a stop never lands inside a
    callback, and the node can still publish its last words (``on_shutdown``, e.g. zero motor
    commands) before the context goes down.
    """
    stop = _StopFlag()
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as e:         # e.g. a --params-file that does not exist or does not parse
        reason = str(e).split(', at ')[0].replace('failed to initialize rcl: ', '')
        sys.stderr.write('%s: cannot start: %s\n' % (name, reason))
        return 2
    try:
        node = node_class()
    except ConfigError as e:
        rclpy.logging.get_logger(name).fatal(str(e))
        rclpy.try_shutdown()
        return 2
    problem = scheduling_problem(scheduling())    # (the realtime prefix asked, and was refused)
    if problem:
        node.get_logger().warning(problem)
    executor = make_executor()
    executor.add_node(node)
    # What start-up made lives as long as the node: out of the collector's way (``gc.freeze``),
    # a full collection looks at what the callbacks made since, not at the node's and the
    # libraries' tens of thousands of objects. In the controller it cost 14 ms, a tick and a
    # half, each time it came (docs/speed.md, "Garbage collection").
    gc.collect()
    gc.freeze()
    try:
        # spin_once in a loop: this rclpy's EventsExecutor.spin() was seen to busy-loop here
        while rclpy.ok() and not stop.raised:
            executor.spin_once(timeout_sec=0.1)
    finally:
        hook = getattr(node, 'on_shutdown', None)
        if hook is not None:
            hook()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


class RefusalLog:
    """Warnings about refused input: each kind of refusal is logged when it first comes, then at
    most once a period while it goes on (rclpy's own throttle is per call site, so one kind would
    hide another).
    """

    def __init__(self, logger, period=1.0):
        self.logger, self.period = logger, period
        self._last = {}

    def warn(self, prefix, reason):
        """Log prefix + reason; the kind is the reason up to its first comma (the values vary)."""
        kind = reason.split(',')[0]
        now = time.monotonic()
        if now - self._last.get(kind, -math.inf) >= self.period:
            self._last[kind] = now
            self.logger.warning(prefix + reason)


class Periodic:
    """Jobs at their own periods, run from one timer (``run`` at its tick): rclpy warns that "the
    number of timers associated with this clock is large" past a handful of timers, and one
    timer is cheaper too. A job late by more than its period runs once, not in a burst.
    """

    def __init__(self):
        self._jobs = []                      # [next due, period, function]

    def every(self, period, function, now=None):
        """Run function every period (s), the first time at the next tick."""
        self._jobs.append([time.monotonic() if now is None else now, period, function])

    def run(self, now=None):
        now = time.monotonic() if now is None else now
        for job in self._jobs:
            if now >= job[0]:
                job[0] = max(job[0] + job[1], now)
                job[2]()
