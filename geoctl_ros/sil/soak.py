"""Load and fault runs over real DDS (the ``soak`` command: ``geoctl_ros.cli.soak``).

Each case flies the sim-in-the-loop (``sim`` and ``controller`` processes on
``config/testbed.yaml``, armed) while loads run beside it or
faults are injected into its inputs, and measures what matters for a vehicle on a joint:

- failsafes (each one is counted, then the controller is re-armed, as an operator would; the
  set-point schedule plays from each arming and then holds R_d),
- input age at the controller's ticks (p99 of its 0.5 s diagnostics windows, and max),
- the gap between motor commands at a subscriber (p99, max) and the control loop period (p99,
  max), and the sensor's closest approach to the cone (from the sim's true attitude, over the
  whole armed flight: the manoeuvre after the arming too).

Loads (other people's processes, in a plain ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` shell):
``cli`` the README's monitoring commands with the real ``ros2`` command in a loop (topic echo,
topic hz, param dump and get on both nodes, service call, service list); ``churn`` a ROS process
joining every second and leaving after 0.5-1.5 s, one in three killed with SIGKILL; ``params``
an rclpy client reading every parameter of both nodes every 0.5 s; ``cpu`` one busy process
per core; ``record`` the flight recorder and the live 3D view, on the nodes' loopback profile
(what recording costs the flight). Faults, through a relay between the sim and the controller:
inputs delayed by 0-10 ms, duplicated, reordered, held back and released in bursts, poses or IMU
missing for a while; and the sim process paused with SIGSTOP/SIGCONT (both inputs missing).

``--transport profile`` (default) runs the nodes on the shipped loopback profile
(``geoctl_ros.sil.rosenv``), ``rmw-default`` on the rmw's defaults (shared memory + UDP,
LOCALHOST): the "before" of docs/interface.md's table. Everything stays on 127.0.0.1.
"""
import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import rclpy
from std_msgs.msg import String

from geoctl_ros.core.telemetry.diagnostics import to_values
from geoctl_ros.nodes.qos import EVENT
from geoctl_ros.sil import measures
from geoctl_ros.sil.loads import start_loads, stop_loads
from geoctl_ros.sil.processes import FLY_CONFIGURED, Monitor, NodeProcess
from geoctl_ros.sil.rosenv import PROFILE_VAR, cli_env, node_env

AGENTS = 'geoctl_ros.sil.loads'

# name: (loads, fault, what). A fault is (kind, argument, period s) or None.
CASES = {
    'idle': ((), None, 'no load, no fault'),
    'monitoring': (('cli',), None, 'the README monitoring commands (ros2 CLI) in a loop'),
    'monitoring+cpu': (('cli', 'cpu'), None, 'the same, and one busy process per core'),
    'monitoring+2cpu': (('cli', 'cpu', 'cpu'), None, 'the same, and two busy processes per core'),
    'churn+params': (('churn', 'params'), None,
                     'processes joining/leaving every second (1 in 3 SIGKILLed), full '
                     'parameter reads every 0.5 s'),
    'all loads': (('cli', 'churn', 'params', 'cpu'), None, 'every load at once'),
    'recording': (('record',), None, 'the flight recorded (record) and drawn (view) beside it'),
    'delayed': ((), ('delay', 0.010, 0), 'inputs delayed by 0-10 ms (so some reordered)'),
    'duplicated': ((), ('duplicate', 0, 0), 'every input sent twice'),
    'reordered': ((), ('reorder', 0, 0), 'one input pair in ten swapped'),
    'bursty': ((), ('hold', 0.080, 1.0), 'inputs held back 80 ms every second, then released'),
    'pose gap 0.4 s': ((), ('drop_pose', 0.4, 5.0), 'no pose for 0.4 s every 5 s'),
    'imu gap 0.15 s': ((), ('drop_imu', 0.15, 5.0), 'no imu for 0.15 s every 5 s'),
    'sim paused 0.15 s': ((), ('pause', 0.15, 5.0), 'sim SIGSTOPped 0.15 s every 5 s'),
    'sim paused 2 s': ((), ('pause', 2.0, 10.0), 'sim SIGSTOPped 2 s every 10 s: failsafe'),
    'monitoring+sim paused 0.15 s': (('cli',), ('pause', 0.15, 10.0),
                                     'sim SIGSTOPped 0.15 s every 10 s, the README monitoring '
                                     'commands (ros2 CLI) in a loop beside it'),
}
RELAYED = ('delay', 'duplicate', 'reorder', 'hold', 'drop_pose', 'drop_imu')

# --- a flight under load ---------------------------------------------------------------------
class Session:
    """sim + controller (+ the relay) + a monitor in this process, armed; stopped by close()."""

    def __init__(self, params_file, out, transport='profile', relay=False, prefix=()):

        env = node_env() if transport == 'profile' else cli_env()
        os.environ.update(env)          # this process's monitor joins the same way
        if PROFILE_VAR not in env:
            os.environ.pop(PROFILE_VAR, None)
        self.env, self.out = env, out
        self.cones = measures.cones_of(params_file)
        os.makedirs(out, exist_ok=True)
        sim_args = ('-r', 'pose:=raw/pose', '-r', 'imu:=raw/imu') if relay else ()
        self.procs = []
        self.sim = NodeProcess('sim', params_file, sim_args, log_dir=out, env=env, prefix=prefix)
        self.procs.append(self.sim)
        if relay:
            self.relay = subprocess.Popen([sys.executable, '-m', AGENTS, 'relay'],
                                          env=env, stdout=subprocess.DEVNULL,
                                          stderr=subprocess.DEVNULL)
        else:
            self.relay = None
        self.controller = NodeProcess('controller', params_file, FLY_CONFIGURED, log_dir=out,
                                      env=env, prefix=prefix)
        self.procs.append(self.controller)
        self._listen_file = os.path.join(out, 'command_times.npy')
        # the listener stands in for the ESC bridge: part of the flight chain, same priority
        self.listener = subprocess.Popen([*prefix, sys.executable, '-m', AGENTS, 'listen',
                                          self._listen_file], env=env,
                                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        rclpy.init()
        self.mon = Monitor(record=('diagnostics', 'true_pose'))

        self._String = String
        self._fault_pub = self.mon.create_publisher(String, 'soak/fault', EVENT)
        self.loads = []
        try:          # whatever goes wrong from here, every process started above is stopped
            if relay:     # a fault command sent before the relay has matched would be lost
                self.mon.wait_for(lambda: self._fault_pub.get_subscription_count() > 0, 40.0,
                                  'the relay')
            # the cone is judged on the sim's true pose over the whole armed flight, the
            # manoeuvre from the arming included: heard here before the arming
            self.mon.wait_for(lambda: self.mon.log['true_pose'], 40.0, "the sim's true pose")
            self.t_armed = time.monotonic()
            reply = self.mon.arm_when_ready(40.0)
            if not reply.success:
                raise RuntimeError('could not arm: ' + reply.message)
            self.mon.spin_for(1.0)
        except BaseException:
            self.close()
            raise

    def fault(self, kind, arg):
        """Start a fault now: a relay mode, or 'pause' (SIGSTOP the sim for arg seconds)."""
        if kind == 'pause':
            self.sim.proc.send_signal(signal.SIGSTOP)
            try:
                self.mon.spin_for(arg)
            finally:
                self.sim.proc.send_signal(signal.SIGCONT)
        else:
            self._fault_pub.publish(self._String(data='%s %g' % (kind, arg)))

    def phase(self, duration, loads=(), fault=None):
        """Fly duration seconds with the loads running and the fault repeating; the figures."""
        mon = self.mon
        self.loads = start_loads(loads, self.env)
        t0 = time.monotonic()
        next_fault = t0 + 1.0
        try:
            while time.monotonic() - t0 < duration:
                if fault is not None and time.monotonic() >= next_fault:
                    kind, arg, period = fault
                    self.fault(kind, arg)
                    next_fault = (time.monotonic() + period) if period else float('inf')
                mon.spin_for(0.1)
                d = mon.last_diagnostic()
                if d is not None and d.figures.failsafe:
                    self.fault('off', 0)
                    mon.wait_for(lambda: mon.arm(True).success, 10.0, 're-arming after a failsafe')
        finally:
            stop_loads(self.loads, self.env)     # the loads' teardown is part of the window
            self.loads = []
            self.fault('off', 0)
            mon.spin_for(1.0)
        self.t_end = time.monotonic()
        with open(os.path.join(self.out, 'diagnostics.jsonl'), 'w') as f:
            for t, d in mon.log['diagnostics']:
                if t0 <= t <= self.t_end:
                    f.write(json.dumps(dict(to_values(d.figures), level=d.level,
                                            message=d.message, t=round(t - t0, 3))) + '\n')
        return measures.figures(mon, t0, self.t_end, self.cones, self.t_armed)

    def command_times(self):
        """Receipt times of motor_commands at the listener (stops it)."""
        if self.listener.poll() is None:
            self.listener.terminate()
            self.listener.wait(10)
        try:
            return np.load(self._listen_file)
        except OSError:
            return np.array([])

    def close(self):
        self.command_times()
        self.mon.destroy_node()
        rclpy.try_shutdown()
        if self.relay is not None:
            self.relay.terminate()
            self.relay.wait(10)
        return [p.stop() for p in self.procs]


def run_cases(names, duration, params_file, out, transport='profile', prefix=(),
              progress=print):
    """Run the named cases, each on a fresh session (relay when a fault needs one); returns
    {name: figures}.
    """
    results = {}
    for k, name in enumerate(names):
        loads, fault, what = CASES[name]
        label = name if names.count(name) == 1 else '%s (%d)' % (name, names[:k].count(name) + 1)
        progress('%s: %s, %.0f s ...' % (label, what, duration))
        relay = fault is not None and fault[0] in RELAYED
        s = Session(params_file, os.path.join(out, re.sub(r'\W+', '_', label)), transport,
                    relay, prefix)
        try:
            f = results[label] = s.phase(duration, loads, fault)
            f['command gap p99/max [ms]'] = measures.command_gaps(s.command_times(),
                                                         s.t_end - f['seconds'], s.t_end)
        finally:
            s.close()
        progress('  ' + measures.table_row(label, f))
    return results
