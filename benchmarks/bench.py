"""Benchmarks of the hot paths, printed against benchmarks/baseline.json.

    ./run shell benchmarks/bench.py                   # print figures and the ratio to the baseline
    ./run shell benchmarks/bench.py --update-baseline # record this machine's figures as the baseline

Figures are microseconds per call (median of several repeats). The control tick must fit in the
control period with room to spare on the ODROID (10 ms at 100 Hz, 2 ms at 500 Hz); the baseline
was measured on the 2-core development machine. Not a test: nothing here passes or fails.
"""
import json
import os
import sys
import timeit

import numpy as np

from geoctl_ros.core import so3
from geoctl_ros.core.loop import ControlLoop
from geoctl_ros.params import CONTROLLER, SIM, controller_setup, resolve, testbed_sim

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


def per_call_us(fn, number):
    times = timeit.repeat(fn, number=number, repeat=5)
    return 1e6 * sorted(times)[len(times) // 2] / number


def measure():
    results = {}
    R = so3.axis_angle([0.2, 0.1, 1.0], 0.4)
    q = so3.rot_to_quat(R)
    w = np.array([0.1, -0.2, 0.3])
    for n in (0, 1, 4, 16):
        loop = ControlLoop(controller_setup(resolve(CONTROLLER, cones(n))))
        loop.offer_pose(q, 0.0, 0.0)
        loop.offer_angular_velocity(w, 0.0, 0.0)
        loop.arm(0.0)
        results['control step, %d cones' % n] = per_call_us(
            lambda: loop.controller.step(R, w, 0.01), 2000)
        results['control tick + mixing, %d cones' % n] = per_call_us(
            lambda: loop.tick(0.001, 0.01), 2000)
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


def main(argv):
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
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
