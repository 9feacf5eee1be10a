"""The processes a soak run starts beside the flight (``geoctl_ros.sil.soak``).

    python -m geoctl_ros.sil.loads relay        # faults between sim and controller
    python -m geoctl_ros.sil.loads listen FILE  # motor_commands receipt times -> FILE.npy

and the load scripts (``CLI_LOOP`` for bash, ``CHURN_LOOP`` and ``PARAMS_LOOP`` for Python) that
stand for other people's processes in a plain LOCALHOST shell.
"""
import heapq
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time

from geometry_msgs.msg import PoseStamped
import numpy as np
import rclpy
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import String

from geoctl_ros.nodes.qos import COMMAND, EVENT, SENSOR
from geoctl_ros.nodes.runtime import make_executor
from geoctl_ros.sil.processes import executable
from geoctl_ros.sil.rosenv import cli_env, node_env

CLI_LOOP = r"""
while true; do
  timeout -k 2 4 ros2 topic echo /cone_margins > /dev/null
  timeout -k 2 4 ros2 topic hz /pose > /dev/null
  ros2 param dump /controller > /dev/null
  ros2 param dump /sim > /dev/null
  ros2 param get /controller k_R > /dev/null
  ros2 param get /sim mass > /dev/null
  ros2 service call /controller/get_parameters rcl_interfaces/srv/GetParameters \
    "{names: [k_R]}" > /dev/null
  ros2 service call /sim/get_parameters rcl_interfaces/srv/GetParameters \
    "{names: [mass]}" > /dev/null
  ros2 service list > /dev/null
  timeout -k 2 3 ros2 topic echo /diagnostics > /dev/null
done
"""

CHURN_LOOP = r"""
import random, signal, subprocess, sys, time
CHILD = ("import rclpy, sys, time\nfrom geometry_msgs.msg import PoseStamped\n"
         "from rclpy.qos import qos_profile_sensor_data\nrclpy.init()\n"
         "n = rclpy.create_node('churn')\n"
         "n.create_subscription(PoseStamped, 'pose', lambda m: None, qos_profile_sensor_data)\n"
         "end = time.monotonic() + float(sys.argv[1])\n"
         "while time.monotonic() < end: rclpy.spin_once(n, timeout_sec=0.05)\n")
rng = random.Random(1)
children = []
k = 0
while True:
    life = rng.uniform(0.5, 1.5)
    p = subprocess.Popen([sys.executable, '-c', CHILD, str(life)], stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    children.append((p, time.monotonic() + 0.7 if k % 3 == 2 else None))
    k += 1
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        for p, kill_at in children:
            if kill_at is not None and time.monotonic() >= kill_at and p.poll() is None:
                p.send_signal(signal.SIGKILL)
        children = [(p, t) for p, t in children if p.poll() is None]
        time.sleep(0.05)
"""

PARAMS_LOOP = r"""
import time, rclpy
from rcl_interfaces.srv import GetParameters, ListParameters
rclpy.init()
n = rclpy.create_node('soak_param_reader')
clients = [(n.create_client(ListParameters, '/%s/list_parameters' % x),
            n.create_client(GetParameters, '/%s/get_parameters' % x))
           for x in ('controller', 'sim')]
def call(c, req):
    if not c.wait_for_service(timeout_sec=2.0):
        return None
    f = c.call_async(req)
    rclpy.spin_until_future_complete(n, f, timeout_sec=2.0)
    return f.result()
while True:
    t = time.monotonic()
    for lc, gc in clients:
        r = call(lc, ListParameters.Request())
        if r is not None:
            call(gc, GetParameters.Request(names=list(r.result.names)))
    rclpy.spin_once(n, timeout_sec=max(0.0, 0.5 - (time.monotonic() - t)))
"""


# --- the relay ------------------------------------------------------------------------------
def relay_main():
    """Republish raw/pose and raw/imu on pose and imu, with the faults commanded on soak/fault."""
    rclpy.init()
    node = rclpy.create_node('soak_relay')
    pubs = {'pose': node.create_publisher(PoseStamped, 'pose', SENSOR),
            'imu': node.create_publisher(Imu, 'imu', SENSOR)}
    state = {'mode': 'off', 'arg': 0.0, 'until': 0.0, 'held': {}, 'seq': 0}
    queue = []                      # (due, seq, stream, msg)
    rng = random.Random(2)

    def on_fault(msg):
        kind, arg = msg.data.split()
        state['mode'], state['arg'] = kind, float(arg)
        state['until'] = time.monotonic() + float(arg)

    def push(due, stream, msg):
        state['seq'] += 1
        heapq.heappush(queue, (due, state['seq'], stream, msg))

    def on_input(stream):
        def cb(msg):
            now = time.monotonic()
            mode, active = state['mode'], now < state['until']
            if mode == 'drop_' + stream and active:
                return
            if mode == 'hold' and active:
                push(state['until'], stream, msg)
            elif mode == 'delay':
                push(now + rng.uniform(0.0, state['arg']), stream, msg)
            elif mode == 'duplicate':
                pubs[stream].publish(msg)
                pubs[stream].publish(msg)
            elif mode == 'reorder':
                held = state['held'].pop(stream, None)
                if held is not None:
                    pubs[stream].publish(msg)
                    pubs[stream].publish(held)
                elif rng.random() < 0.1:
                    state['held'][stream] = msg
                else:
                    pubs[stream].publish(msg)
            else:
                pubs[stream].publish(msg)
        return cb

    def flush():
        now = time.monotonic()
        while queue and queue[0][0] <= now:
            _, _, stream, msg = heapq.heappop(queue)
            pubs[stream].publish(msg)

    node.create_subscription(PoseStamped, 'raw/pose', on_input('pose'), SENSOR)
    node.create_subscription(Imu, 'raw/imu', on_input('imu'), SENSOR)
    node.create_subscription(String, 'soak/fault', on_fault, EVENT)
    node.create_timer(0.001, flush)
    signal.signal(signal.SIGTERM, lambda *a: sys.exit(0))
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, SystemExit):
        pass
    return 0


def listen_main(path):
    """A subscriber to motor_commands alone (as an ESC bridge would be): writes the receipt times
    (CLOCK_MONOTONIC, shared by every process) to path when stopped with SIGTERM.
    """
    rclpy.init()
    node = rclpy.create_node('soak_command_listener')
    stamps = []
    node.create_subscription(JointState, 'motor_commands',
                             lambda m: stamps.append(time.monotonic()),
                             COMMAND)
    stop = []
    signal.signal(signal.SIGTERM, lambda *a: stop.append(1))
    executor = make_executor()
    executor.add_node(node)
    while not stop:
        executor.spin_once(timeout_sec=0.1)
    np.save(path, np.array(stamps))
    return 0



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


if __name__ == '__main__':
    if sys.argv[1:2] == ['relay']:
        sys.exit(relay_main())
    if sys.argv[1:2] == ['listen'] and len(sys.argv) == 3:
        sys.exit(listen_main(sys.argv[2]))
    sys.exit('usage: python -m geoctl_ros.sil.loads relay | listen FILE')
