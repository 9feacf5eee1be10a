"""Benchmarks of the hot paths, printed against benchmarks/baseline.json.

    ./run shell benchmarks/bench.py                   # print figures and the ratio to the baseline
    ./run shell benchmarks/bench.py --update-baseline  # this machine's figures as the baseline
    ./run shell benchmarks/bench.py --against REV [--rounds 3]  # this tree against a revision
                                                      # (against.py)
    ./run --odroid shell benchmarks/bench.py ...      # the same on the vehicle's stack

Figures are microseconds per call (the fastest of several repeats). The control tick must fit in
the control period with room to spare on the ODROID (10 ms at 100 Hz, 2 ms at 500 Hz); the baseline
was measured on the 2-core development machine. Not a test: nothing here passes or fails.

Then, side by side in the same run (so that a busy machine slows both alike): the control step
against ``paper_law.py``, a plain numpy transcription of the paper's law with a loop over cones,
at 1, 4, 16 and 64 cones (after checking that both give the same moment); the controller node's
tick in-process (imu callback to motor command published, and the whole callback with the
monitoring topics after it; p50, p99, max); the campaign's batched closed loop
(``geoctl_ros.sim.closed_loop``): its real-time factor per core for batches of 1 to 256 runs; and
input-to-command latency over DDS against a bare relay node (``latency.py``; ``--no-latency``
skips it).
"""
import geoctl_ros  # (first: numpy as the package's processes have it, geoctl_ros/__init__.py)

# isort: split
import gc
import json
import os
import subprocess
import sys
import time
import timeit

from geometry_msgs.msg import PoseStamped
import latency
import numpy as np
from paper_law import PaperLaw
import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import Imu

from geoctl_ros.campaign import manoeuvres
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.supervisor.loop import ControlLoop
from geoctl_ros.nodes.controller import ControllerNode
from geoctl_ros.nodes.conversions import set_quaternion, set_vector, time_msg
from geoctl_ros.params import (
    CONTROLLER,
    SIM,
    controller_setup,
    load_parameter_file,
    resolve,
)
from geoctl_ros.sil.rosenv import use_node_env
from geoctl_ros.sim import scenario
from geoctl_ros.sim.closed_loop import fly
from geoctl_ros.sim.testbed import testbed_sim

HERE = os.path.dirname(os.path.abspath(__file__))
BASELINE = os.path.join(HERE, 'baseline.json')


def cones(n):
    rng = np.random.default_rng(0)
    names = ['c%d' % i for i in range(n)]
    out = {'cones.names': names}
    for name in names:
        v = rng.normal(size=3)
        v[0] = -abs(v[0])                      # keep the sensor (+x at R = I) clear
        out['cones.%s.axis' % name] = [float(x) for x in v]
        out['cones.%s.half_angle_deg' % name] = 10.0
    return out


def per_call_us(fn, number, repeat=5):
    """The fastest of `repeat` timings of `number` calls: on a shared machine the other processes
    only ever add time, so the minimum is the figure that measures the code.
    """
    return 1e6 * min(timeit.repeat(fn, number=number, repeat=repeat)) / number


def measure():
    results = {}
    R = so3.axis_angle([0.2, 0.1, 1.0], 0.4)
    q = so3.rot_to_quat(R)
    w = np.array([0.1, -0.2, 0.3])
    for n in (0, 1, 4, 16):
        # (arms on one sample: the sensor checks' windows are not what this measures)
        loop = ControlLoop(controller_setup(resolve(CONTROLLER, dict(
            cones(n), consistency_checks=False))))
        loop.offer_pose(q, 0.0, 0.0)
        loop.offer_angular_velocity(w, 0.0, 0.0)
        loop.arm(0.0)
        results['control step, %d cones' % n] = per_call_us(
            lambda: loop.controller.step(R, w, 0.01), 2000)
        results['control tick + mixing, %d cones' % n] = per_call_us(   # estimate held at 0
            lambda: (loop.tick(0.001, 0.01), loop.reset_adaptation()), 2000)
    setup = controller_setup(resolve(CONTROLLER, {}))
    results['allocation, feasible'] = per_call_us(
        lambda: setup.mixer.allocator.allocate(np.array([0.1, 0.05, 0.02]), 12.4), 2000)
    results['allocation, saturated'] = per_call_us(
        lambda: setup.mixer.allocator.allocate(np.array([5.0, 2.0, 1.0]), 12.4), 2000)
    sim = testbed_sim(resolve(SIM, {}))
    cmd = np.full(6, 118)
    results['sim step (rotors), 1 ms'] = per_call_us(lambda: sim.step(cmd, 1e-3), 2000)
    results['so3.exp'] = per_call_us(lambda: so3.exp(w), 20000)
    return results


def side_by_side():
    """(rows of n cones, ours us, transcription us, ratio, max |u difference|), node tick us."""
    R = so3.axis_angle([0.2, 0.1, 1.0], 0.4)
    w = np.array([0.1, -0.2, 0.3])
    rows = []
    for n in (1, 4, 16, 64):
        values = resolve(CONTROLLER, dict(cones(n), **{'cog_offset': [0.0, 0.0, 0.0],
                                                        'gravity_compensation': False}))
        setup = controller_setup(values)
        ours = ControlLoop(setup).controller
        cfg = setup.config
        paper = PaperLaw(cfg.J, cfg.G, cfg.k_R, cfg.k_Omega, cfg.k_Delta, cfg.c,
                         cfg.cones.alpha, cfg.cones.r, cfg.cones.V, cfg.cones.theta)
        assert not cfg.cones.evaluate(R).saturated.any()
        diff = float(np.abs(ours.step(R, w, 0.0).u - paper.step(R, w, 0.0)[0]).max())
        t_ours, t_paper = [], []
        for _ in range(15):                     # interleaved, so that load hits both alike
            t_ours.append(per_call_us(lambda: ours.step(R, w, 0.0), 300, 1))
            t_paper.append(per_call_us(lambda: paper.step(R, w, 0.0), 300, 1))
        a, b = min(t_ours), min(t_paper)
        rows.append((n, a, b, b / a, diff))
    return rows, node_tick_us()


def node_tick_us(samples=3000):
    """The controller node's tick in this process (rclpy on the loopback profile, no subscribers
    matched), with ``step_on: imu`` as a flight would run it: a pose, then an imu sample whose
    callback runs the step, and what start-up made frozen out of the collector's way, as a
    node's process has it (``nodes/runtime.py``). Returns (us from the start of the imu callback
    to the motor command published, us for the whole callback with the monitoring topics), each
    as (p50, p99, max).
    """
    use_node_env()

    rclpy.init()
    try:
        testbed = os.path.join(os.path.dirname(HERE), 'config', 'testbed.yaml')
        node = ControllerNode(cli_args=['--ros-args', '--params-file', testbed],
                              parameter_overrides=[Parameter('step_on', value='imu'),
                                                   Parameter('consistency_checks', value=False)])

        pose, imu = PoseStamped(), Imu()
        # the testbed near its set point (its schedule's first, if it has one): 5 deg off it,
        # turning at 0.1 rad/s
        setup = node.loop.setup
        R_d0 = setup.schedule.rotations[0] if len(setup.schedule) else setup.setpoint
        set_quaternion(pose.pose.orientation,
                       so3.rot_to_quat(R_d0 @ so3.axis_angle([0.2, 0.1, 1.0], np.radians(5.0))))
        set_vector(imu.angular_velocity, (0.05, -0.05, 0.07))
        publisher, published = node.pub_motors, [0.0]
        gc.collect()              # (as nodes/runtime.py's spin does once the node is built: what
        gc.freeze()               # start-up made is out of the collector's way)

        class Timed:                  # the motor publisher, noting when its publish returns
            topic_name = publisher.topic_name

            def publish(self, msg):
                publisher.publish(msg)
                published[0] = time.perf_counter()
        node.pub_motors = Timed()
        t = [0.0]
        to_motors, whole = [], []
        for k in range(samples + 1):
            t[0] += 0.01
            pose.header.stamp = imu.header.stamp = time_msg(t[0])
            node._on_pose(pose)
            node.loop.reset_adaptation()    # else the estimate winds up at one attitude
            t0 = time.perf_counter()
            node._on_imu(imu)
            t1 = time.perf_counter()
            if k == 0:
                assert node.loop.arm(node._now()).ok
                continue
            to_motors.append(published[0] - t0)
            whole.append(t1 - t0)
        node.pub_motors = publisher
        gc.unfreeze()
        node.destroy_node()
        return tuple(tuple(1e6 * np.percentile(v, q) for q in (50, 99, 100))
                     for v in (to_motors, whole))
    finally:
        rclpy.try_shutdown()


def batched():
    """Rows (runs in the batch, wall seconds per simulated second, real-time factor per core) of
    the campaign's batched closed loop (testbed, rotors, 1 kHz integration, one cone).
    """
    base = load_parameter_file(os.path.join(os.path.dirname(HERE), 'config', 'testbed.yaml'))
    pool, i = [], 0
    while len(pool) < 256:
        sections = manoeuvres.run_sections(base, 1, i, 1.0)
        if manoeuvres.cone_count(1, i) == 1:
            pool.append(scenario.from_sections(sections, 'run_%d' % i))
        i += 1
    rows = []
    for n in (1, 16, 64, 256):
        wall = min(fly(pool[:n]).wall_s for _ in range(2))
        rows.append((n, wall, n * 1.0 / wall))
    return rows


# The figure groups a tree is measured by, each named by the function of its bench.py that
# measures it (every revision since --json has them), and how a group's result reads as figures
GROUPS = ('measure', 'side_by_side', 'batched')


def named(group, result):
    """A group's result as figures: name -> microseconds (for the batched loop, microseconds of
    wall time per simulated second per run).
    """
    if group == 'measure':
        return dict(result)
    out = {}
    if group == 'side_by_side':
        rows, tick = result
        for n, a, _, _, _ in rows:
            out['control step vs transcription, %d cones' % n] = a
        for label, (p50, p99, _) in zip(('node tick to motor command', 'node tick, whole'), tick):
            out[label + ' p50'], out[label + ' p99'] = p50, p99
        return out
    for n, wall, _ in result:
        out['batched loop, %d runs, per run-second' % n] = 1e6 * wall / n
    return out


def figures():
    """The figures that can be set side by side across trees and stacks (``named``)."""
    out = {}
    for group in GROUPS:
        out.update(named(group, globals()[group]()))
    return out


def main(argv):
    if '--json' in argv:
        out = figures()
        out['tree'] = os.path.dirname(os.path.dirname(os.path.abspath(geoctl_ros.__file__)))
        print(json.dumps(out))
        return 0
    if '--against' in argv:
        rounds = int(argv[argv.index('--rounds') + 1]) if '--rounds' in argv else 3
        # (a program of its own: against.py imports this module, not the other way round)
        return subprocess.call([sys.executable, os.path.join(HERE, 'against.py'),
                                argv[argv.index('--against') + 1], str(rounds)])
    results = measure()
    if '--update-baseline' in argv:
        with open(BASELINE, 'w') as f:
            json.dump({k: round(v, 2) for k, v in results.items()}, f, indent=2)
            f.write('\n')
        print('baseline written to %s' % BASELINE)
    baseline = {}
    if os.path.exists(BASELINE):
        with open(BASELINE) as f:
            baseline = json.load(f)
    print('%-36s %10s %10s %8s' % ('benchmark', 'us/call', 'baseline', 'ratio'))
    for k, v in results.items():
        b = baseline.get(k)
        print('%-36s %10.1f %10s %8s' % (k, v, '%.1f' % b if b else '-',
                                         '%.2f' % (v / b) if b else '-'))
    rows, tick = side_by_side()
    print()
    print('%-8s %14s %18s %8s %14s' % ('cones', 'control step', 'paper transcription',
                                        'ratio', 'max |u diff|'))
    for n, a, b, ratio, diff in rows:
        print('%-8d %11.1f us %15.1f us %8.2f %14.1e' % (n, a, b, ratio, diff))
    print('64 cones / 4 cones (ours): %.2f' % (rows[3][1] / rows[1][1]))
    print()
    print('controller node, in-process, step_on: imu    p50 us   p99 us   max us')
    for label, (p50, p99, top) in zip(('imu callback -> motor command published',
                                       'whole callback (+ 6 monitoring topics)'), tick):
        print('%-42s %8.0f %8.0f %8.0f' % (label, p50, p99, top))
    print()
    print('batched closed loop (campaign): runs, wall s per simulated s, '
          'real-time factor per core')
    for n, wall, rtf in batched():
        print('%6d %10.3f s %10.0f' % (n, wall, rtf))
    if '--no-latency' not in argv:
        print()
        print(latency.table(latency.measure(10.0)))
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
