"""Load and fault runs over real DDS: does the lab's own workflow ever drop the testbed?

    ./run soak                                   # every case, 60 s each, prints a table
    ./run soak --case monitoring --duration 600  # the README's monitoring commands for 10 min
    ./run soak --transport rmw-default ...       # the same with the rmw's default transports

Each case flies the sim-in-the-loop (``sim`` and ``controller`` processes on
``config/testbed.yaml``, armed) while loads run beside it or
faults are injected into its inputs, and measures what matters for a vehicle on a joint:

- failsafes (each one is counted, then the controller is re-armed, as an operator would; the
  set-point schedule plays from each arming and then holds R_d),
- input age at the controller's ticks (p99 of its 0.5 s diagnostics windows, and max),
- the gap between motor commands at a subscriber (p99, max) and the control loop period (p99,
  max), and the sensor's closest approach to the cone (from the sim's true attitude).

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
(``geoctl_ros.tools.rosenv``), ``rmw-default`` on the rmw's defaults (shared memory + UDP,
LOCALHOST): the "before" of docs/interface.md's table. Everything stays on 127.0.0.1.
"""
import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
import rclpy
from std_msgs.msg import String

from geoctl_ros.core import so3
from geoctl_ros.core.diagnostics import WARN, aggregate_ms, to_values
from geoctl_ros.nodes.qos import EVENT
from geoctl_ros.params import (
    CONTROLLER,
    cone_set,
    load_parameter_file,
    node_overrides,
    resolve,
)
from geoctl_ros.tools.processes import Monitor, NodeProcess, executable
from geoctl_ros.tools.rosenv import PROFILE_VAR, cli_env, config_dir, node_env
from geoctl_ros.tools.soak_agents import CHURN_LOOP, CLI_LOOP, PARAMS_LOOP

AGENTS = 'geoctl_ros.tools.soak_agents'

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
        self.cones = _cones(params_file)
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
        self.controller = NodeProcess('controller', params_file, log_dir=out, env=env,
                                      prefix=prefix)
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
        return figures(mon, t0, self.t_end, self.cones)

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


def ros2_command():
    """The `ros2` command beside this interpreter (the venv's) or on PATH, or None."""
    return (shutil.which('ros2', path=os.path.dirname(sys.executable))
            or shutil.which('ros2'))


def start_loads(loads, env):
    """Start the named loads (CASES) as other people's processes in a plain LOCALHOST shell
    beside nodes started with env; the processes, for stop_loads.
    """
    env = cli_env(env)
    procs = []
    try:
        for load in loads:
            if load == 'cli':
                ros2 = ros2_command()
                if ros2 is None:
                    raise RuntimeError('the cli load needs the ros2 command (README, '
                                       '"Set-up: two commands")')
                env_cli = dict(env, PATH=os.path.dirname(ros2) + os.pathsep + env.get('PATH', ''))
                procs.append(subprocess.Popen(['bash', '-c', CLI_LOOP], env=env_cli,
                                              stdout=subprocess.DEVNULL,
                                              stderr=subprocess.DEVNULL, start_new_session=True))
            elif load in ('churn', 'params'):
                code = CHURN_LOOP if load == 'churn' else PARAMS_LOOP
                procs.append(subprocess.Popen([sys.executable, '-c', code], env=env,
                                              stdout=subprocess.DEVNULL,
                                              stderr=subprocess.DEVNULL, start_new_session=True))
            elif load == 'record':          # a lab's recorder and 3D view, ros2 run as they are
                bag = os.path.join(tempfile.mkdtemp(prefix='soak-record-'), 'flight')
                for name, args in (('record', ['-p', 'record.path:=' + bag]), ('view', [])):
                    procs.append(subprocess.Popen(
                        [executable(name) or name, '--ros-args', *args], env=node_env(),
                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                        start_new_session=True))
                    procs[-1].node = True
            elif load == 'cpu':
                for _ in range(os.cpu_count() or 1):
                    procs.append(subprocess.Popen([sys.executable, '-c', 'while True: pass'],
                                                  start_new_session=True))
            else:
                raise ValueError('unknown load %r' % load)
    except BaseException:
        stop_loads(procs, env)
        raise
    return procs


def stop_loads(procs, env):
    """Stop what start_loads started (each with its process group) and the `ros2` daemon that
    the cli load spawns.
    """
    for p in procs:       # SIGKILL, but Ctrl-C first for a node (a recorder closes its bag)
        try:
            if getattr(p, 'node', False):
                os.killpg(p.pid, signal.SIGINT)
                p.wait(5.0)
        except ProcessLookupError:
            pass
        except subprocess.TimeoutExpired:
            pass
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        p.wait()
    ros2 = ros2_command()
    if ros2 is not None:
        subprocess.run([ros2, 'daemon', 'stop'], env=cli_env(env), stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL, timeout=30)


def _windows(diags, name):
    """(p99 over the windows' p99, max) of a windowed figure of the controller's diagnostics
    (a Figures field), ms.
    """
    w = aggregate_ms(diags, name)
    return (float('nan'), float('nan')) if w is None else (w.p99, w.max)


def _cones(params_file):
    return cone_set(resolve(CONTROLLER, node_overrides(load_parameter_file(params_file),
                                                       CONTROLLER)))


def command_gaps(times, t0, t1):
    """(p99, max) of the gaps between command receipts within [t0, t1], ms."""
    t = times[(times >= t0) & (times <= t1)]
    if len(t) < 2:
        return float('nan'), float('nan')
    gaps = np.diff(t) * 1e3
    return float(np.percentile(gaps, 99)), float(gaps.max())


def figures(mon, t0, t1, cones):
    """The figures of the flight between t0 and t1 (monotonic, as the monitor's log)."""
    diags = [d for t, d in mon.log['diagnostics'] if t0 <= t <= t1]
    failed = [d.figures.failsafe for d in diags]
    failsafes = sum(1 for a, b in zip([False] + failed, failed) if b and not a)
    margins = [float(np.min(cones.margins_deg(so3.quat_to_rot(q))))
               for t, (_, q) in mon.log['true_pose'] if t0 <= t <= t1] if len(cones) else [np.nan]
    last = diags[-1].figures if diags else None
    out = {
        'seconds': t1 - t0,
        'failsafes': failsafes,
        'warn windows': sum(1 for d in diags if d.level == WARN),
        'pose age p99/max [ms]': _windows(diags, 'pose_age_at_tick'),
        'imu age p99/max [ms]': _windows(diags, 'imu_age_at_tick'),
        'loop period p99/max [ms]': _windows(diags, 'loop_period'),
        'pose to command p99/max [ms]': _windows(diags, 'pose_to_command_latency'),
        'closest approach [deg]': min(margins) if margins else float('nan'),
        'gaps ridden (pose, imu)': (('-', '-') if last is None else
                                    (last.pose_gaps.count, last.imu_gaps.count)),
    }
    return out


TABLE_HEAD = ('| case | s | failsafes | pose age p99 / max, ms | imu age p99 / max, ms | '
              'command gap p99 / max, ms | loop period p99 / max, ms | '
              'pose to command p99 / max, ms | min cone margin, deg |\n'
              '|---|---|---|---|---|---|---|---|---|')


def table_row(name, f):
    def pair(p):
        return '%.1f / %.1f' % p
    return '| %s | %.0f | %d | %s | %s | %s | %s | %s | %.1f |' % (
        name, f['seconds'], f['failsafes'], pair(f['pose age p99/max [ms]']),
        pair(f['imu age p99/max [ms]']), pair(f['command gap p99/max [ms]']),
        pair(f['loop period p99/max [ms]']), pair(f['pose to command p99/max [ms]']),
        f['closest approach [deg]'])


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
            f['command gap p99/max [ms]'] = command_gaps(s.command_times(),
                                                         s.t_end - f['seconds'], s.t_end)
        finally:
            s.close()
        progress('  ' + table_row(label, f))
    return results


def main(argv=None):
    parser = argparse.ArgumentParser(prog='soak', description=__doc__.split('\n\n')[0])
    parser.add_argument('--case', action='append', choices=sorted(CASES),
                        help='a case to run (repeatable; default: all)')
    parser.add_argument('--duration', type=float, default=60.0, help='seconds per case (60)')
    parser.add_argument('--transport', choices=('profile', 'rmw-default'), default='profile',
                        help='the nodes on the loopback profile (default) or the rmw defaults')
    parser.add_argument('--params-file', default=None, help='default: config/testbed.yaml')
    parser.add_argument('--prefix', default='',
                        help="run sim and controller under this command, as ros2 run --prefix "
                             "(e.g. 'nice -n -10'; docs/interface.md, \"Scheduling\")")
    parser.add_argument('--out', default=None, help='folder for logs and soak.json')
    args = parser.parse_args(argv)
    params_file = args.params_file or os.path.join(config_dir(), 'testbed.yaml')
    out = args.out or tempfile.mkdtemp(prefix='soak-')
    names = args.case or list(CASES)
    results = run_cases(names, args.duration, params_file, out, args.transport,
                        args.prefix.split(),
                        progress=lambda m: print(m, file=sys.stderr, flush=True))
    with open(os.path.join(out, 'soak.json'), 'w') as f:
        json.dump({'transport': args.transport, 'results': results}, f, indent=2)
    print('transport: %s, %s%s' % (args.transport, os.path.basename(params_file),
                                    ', nodes under ' + args.prefix if args.prefix else ''))
    print(TABLE_HEAD)
    for label, f in results.items():
        print(table_row(label, f))
    print('logs and soak.json in %s' % out)
    return 0


if __name__ == '__main__':
    sys.exit(main())
