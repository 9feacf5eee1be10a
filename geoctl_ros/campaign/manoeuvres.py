"""The campaign's random manoeuvres, and each as an ordinary scenario (``run_sections``) or a
scenario file (``write_scenario_file``); flown by ``geoctl_ros.campaign.runner``.

The distribution (run i of seed S draws from its own seed, ``SeedSequence(S).spawn(N)[i]``, for
any N > i: a run does not depend on how many others there are, nor on where or with which it is
flown; its first child seed draws the number of cones, so that a campaign can batch its runs by
cone count without drawing them, and its second everything else):

- cones: 1-4 (uniform: the count is drawn once, then the cones are placed until they fit),
  half-angles uniform in 10-35 deg, axes at a uniform azimuth and an elevation uniform within
  +-20 deg of the horizon (where a body-fixed sensor of a testbed on a joint can point), every two
  cones at least 10 deg apart (edge to edge), so there is always a way round;
- the manoeuvre: the sensor starts 5-30 deg outside the first cone (uniform, at a uniform azimuth
  round its axis) and its goal is 5-30 deg outside the same cone on the far side (azimuth 150-210
  deg away), so the straight way crosses the cone and the controller must go round; start and goal
  are at least 5 deg clear of every cone, and the goal is one the controller accepts with
  ``unmodelled_moment_max`` set to what the errors below can add up to (``unmodelled_moment``,
  0.40 N m for the testbed; redrawn otherwise). About the sensor axis, start and goal attitudes
  are the most upright ones turned by up to +-15 deg, and the body's z axis is within 40 deg of
  vertical (the joint's range; redrawn otherwise);
- the testbed (``config/testbed.yaml``): its gains, rotors, thrust curve, 40 ms motor lag and
  saturation, motion-capture (0.1 deg) and gyro (0.005 rad/s) noise, 100 Hz control, 1 kHz
  integration, 20 s;
- per run: measurement latency 0-60 ms (whole ms, uniform), and input stalls, 0.5 a second on
  average (Poisson), each 10-40 ms (whole ms, uniform), so the controller's inputs are up to
  100 ms old, as the sim-in-the-loop measured them on a busy machine; a constant disturbance of
  uniform direction and magnitude up to 0.05 N m (``--disturbance-max``; with the gravity moment
  of the errors below the estimate sees at most 0.40 N m, within its bound delta_bar_max =
  1 N m); the
  true mass off by up to +-20 %; the true inertia's mass distribution stretched by up to +-20 %
  along each body axis (second moment E = tr(J)/2 I - J -> S E S, S = diag(sqrt(f)), f uniform
  0.8-1.2; J = tr(E) I - E stays a physical inertia); the true centre-of-mass offset scaled by
  0.8-1.2.
"""
import math
import os
from typing import NamedTuple, Tuple

import numpy as np

from geoctl_ros.core.geometry import so3, sphere
from geoctl_ros.core.law.control import AttitudeController
from geoctl_ros.params import (
    CONTROLLER,
    SIM,
    cone_set,
    controller_config,
    node_overrides,
    resolve,
    write_parameter_file,
)
from geoctl_ros.params.build import cone_values
from geoctl_ros.params.scenario import goal_check
from geoctl_ros.params.testbed import testbed_setup

CLEAR_DEG = 5.0                    # start and goal at least this far outside every cone
GAP_DEG = 10.0                     # edge-to-edge distance between two cones, at least
UP = np.array([0.0, 0.0, 1.0])
_ARC = np.linspace(0.0, 1.0, 41)      # points on the straight way from start to goal
_TWISTS = np.radians(np.arange(-180.0, 180.0, 2.0))     # turns about the sensor axis tried
PLACEMENTS = 64                    # candidate placements of the cones drawn at once
TILT_DEG = 40.0                    # the body's z axis within this of vertical at start and goal
TWIST_DEG = 15.0                   # turn about the sensor axis from the most upright attitude
CONE_ELEVATION_DEG = 20.0          # cone axes within this of the horizon
DISTURBANCE_MAX = 0.05             # N m, largest constant disturbance (docs/campaigns.md)
MODEL_ERROR = 0.2                  # true mass, inertia stretch and centre of mass within +-20 %
LATENCY_MS_MAX = 60                # measurement latency 0..this (whole ms, uniform)
STALL_RATE = 0.5                   # input stalls per second (Poisson)
STALL_MS = (10, 40)                # each stall's length (whole ms, uniform)


class Stratum(NamedTuple):
    """Where a campaign's runs are drawn from: the sensor's start outside the first cone (deg,
    uniform), the measurement latency (whole ms, uniform) and how the runs start (``starts``:
    held, resting on the joint's stops, or half of each); the rest of the draw is the same.
    """

    start_clear_deg: Tuple[float, float] = (5.0, 30.0)
    latency_ms: Tuple[int, int] = (0, LATENCY_MS_MAX)
    starts: Tuple[str, ...] = ('held',)


# 'all': the campaign's draw; 'near-cone': its hardest part, where every close approach of the
# 10,000-run campaigns started (5-11 deg from a cone, 30-60 ms of latency; docs/campaigns.md);
# 'arming': armed 2.25-5 deg from a cone (the arming checks' guard and just past it), half of the
# runs resting on the joint's stops, half held, with the rest of the draw (the take-over's check
# refuses some: ``Flight.takeover_margin_deg``)
STRATA = {'all': Stratum(), 'near-cone': Stratum((5.0, 11.0), (30, LATENCY_MS_MAX)),
          'arming': Stratum((2.25, 5.0), (0, LATENCY_MS_MAX), ('held', 'resting'))}


def _aligning(r, d):
    """The rotation by the shortest arc that takes r to d (unit vectors, not opposite)."""
    axis = so3.cross(r, d)
    return so3.exp(axis / max(np.linalg.norm(axis), 1e-12)
                   * math.atan2(np.linalg.norm(axis), float(r @ d)))


def angle_deg(a, b):
    """The angle between unit vectors a and b (deg)."""
    return math.degrees(math.acos(min(1.0, max(-1.0, float(a @ b)))))


def upright(r, d, turn_deg):
    """An attitude with the sensor axis r pointing along d and the body as upright as it can be,
    then turned about d by turn_deg; None if that leaves the body tilted more than TILT_DEG (the
    joint's range).
    """
    base = _aligning(r, d)
    ups = so3.exp_apply(d * _TWISTS[:, None], base @ UP)        # body z for each twist
    twist = _TWISTS[int(np.argmax(ups[:, 2]))] + math.radians(turn_deg)
    R = so3.exp(d * twist) @ base
    return R if angle_deg(R @ UP, UP) <= TILT_DEG else None


def _attitude(rng, r, d):
    """``upright`` turned by a uniform draw within +-TWIST_DEG."""
    return upright(r, d, rng.uniform(-TWIST_DEG, TWIST_DEG))


def on_the_stops(rng, r, d, tilt_max_deg):
    """An attitude with the sensor axis r along d whose body z axis is tilted exactly
    tilt_max_deg from vertical (resting on the joint's stops), turned about d one way or the
    other (drawn); None if no turn about d tilts it that far or if the least tilt is already
    past it. Turning the most upright attitude U by psi about d: cos(tilt) = A cos psi +
    B sin psi + C (A, B, C from d, U's z axis and up), solved for psi.
    """
    base = upright(r, d, 0.0)
    if base is None:
        return None
    z = base @ UP
    C = float(UP @ d) * float(d @ z)
    A = float(UP @ z) - C
    B = float(UP @ np.cross(d, z))
    K = math.cos(math.radians(tilt_max_deg)) - C
    size = math.hypot(A, B)
    if size < 1e-12 or abs(K) > size:
        return None
    psi = math.atan2(B, A) + (1.0 if rng.uniform() < 0.5 else -1.0) * math.acos(K / size)
    return so3.exp(d * psi) @ base


def crosses(d0, d1, axis, half_angle_deg):
    """Whether the straight way of the sensor from d0 to d1 crosses the cone (axis, half-angle)."""
    arc = (1.0 - _ARC[:, None]) * d0 + _ARC[:, None] * d1
    cos_arc = (arc @ axis) / np.sqrt(np.sum(arc * arc, axis=1))
    return math.degrees(math.acos(min(1.0, float(cos_arc.max())))) < half_angle_deg


def run_seeds(seed, index):
    """The seeds of run index of campaign seed: the children of SeedSequence(seed).spawn(N)
    [index] (the cone count's, everything else's, and how it starts).
    """
    return np.random.SeedSequence(seed, spawn_key=(index,)).spawn(3)


def cone_count(seed, index):
    """The number of cones of run index (cheap: without drawing the rest of the run)."""
    return int(np.random.default_rng(run_seeds(seed, index)[0]).integers(1, 5))


def start_of(seed, index, stratum='all'):
    """How run index starts (``Stratum.starts``; cheap, as ``cone_count``: a batch shares it)."""
    starts = STRATA[stratum].starts
    if len(starts) == 1:
        return starts[0]
    return starts[int(np.random.default_rng(run_seeds(seed, index)[2]).integers(len(starts)))]


def _place_cones(rng, n):
    """n cones that fit (half-angles in deg, unit axes): the first that fits of blocks of
    PLACEMENTS candidate placements drawn at once.
    """
    upper = np.triu(np.ones((n, n), dtype=bool), 1)
    while True:
        theta = rng.uniform(10.0, 35.0, (PLACEMENTS, n))
        elevation = np.radians(rng.uniform(-CONE_ELEVATION_DEG, CONE_ELEVATION_DEG,
                                           (PLACEMENTS, n)))
        azimuth = rng.uniform(0.0, 2.0 * math.pi, (PLACEMENTS, n))
        axes = np.stack([np.cos(elevation) * np.cos(azimuth),
                         np.cos(elevation) * np.sin(azimuth), np.sin(elevation)], axis=-1)
        between = np.degrees(np.arccos(np.clip(axes @ axes.transpose(0, 2, 1), -1.0, 1.0)))
        fits = np.all((between >= theta[:, :, None] + theta[:, None, :] + GAP_DEG) | ~upper,
                      axis=(1, 2))
        if fits.any():
            k = int(np.argmax(fits))
            return theta[k], list(axes[k])


def draw_manoeuvre(seed, index, sensor_axis, goal_ok=None, duration=20.0, stratum='all',
                   tilt_max_deg=180.0):
    """The random part of run index of campaign seed: a dict of per-run values. goal_ok(cones,
    R_d) (cones as [(axis, half-angle deg)]), if given, must accept the goal (else redrawn).
    stratum: the part of the draw (``STRATA``; the same random numbers, other bounds);
    tilt_max_deg: the joint's stops, where a run that starts resting on them rests.
    """
    start = start_of(seed, index, stratum)
    part = STRATA[stratum]
    n = cone_count(seed, index)
    rng = np.random.default_rng(run_seeds(seed, index)[1])
    r = sphere.unit(np.asarray(sensor_axis, dtype=float))
    while True:
        theta, axes = _place_cones(rng, n)
        v0, th0 = axes[0], math.radians(theta[0])
        azimuth = rng.uniform(0.0, 2.0 * math.pi)
        d0 = sphere.direction(v0, th0 + math.radians(rng.uniform(*part.start_clear_deg)),
                              azimuth)
        d1 = sphere.direction(v0, th0 + math.radians(rng.uniform(5.0, 30.0)),
                        azimuth + math.pi + math.radians(rng.uniform(-30.0, 30.0)))
        # (the start's clearance from the first cone is the stratum's: the arming stratum
        # starts within CLEAR_DEG of it)
        clear = min(CLEAR_DEG, part.start_clear_deg[0])
        if (any(angle_deg(d1, v) < t + CLEAR_DEG for v, t in zip(axes, theta))
                or angle_deg(d0, v0) < theta[0] + clear
                or any(angle_deg(d0, v) < t + CLEAR_DEG for v, t in zip(axes[1:], theta[1:]))):
            continue
        if not crosses(d0, d1, v0, theta[0]):
            continue                                    # the straight way misses the cone
        R0, R_d = _attitude(rng, r, d0), _attitude(rng, r, d1)
        if start == 'resting':
            R0 = on_the_stops(rng, r, d0, tilt_max_deg)
        if R0 is not None and R_d is not None and (
                goal_ok is None or goal_ok(list(zip(axes, theta)), R_d)):
            break
    push = sphere.unit(rng.normal(size=3))
    return {
        'cones': [(list(map(float, v)), float(t)) for v, t in zip(axes, theta)],
        'R0': R0, 'R_d': R_d,
        'latency_ms': int(rng.integers(part.latency_ms[0], part.latency_ms[1] + 1)),
        'disturbance': push * rng.uniform(0.0, 1.0),      # times --disturbance-max
        'mass_factor': rng.uniform(1.0 - MODEL_ERROR, 1.0 + MODEL_ERROR),
        'inertia_factors': rng.uniform(1.0 - MODEL_ERROR, 1.0 + MODEL_ERROR, 3),
        'cog_factor': rng.uniform(1.0 - MODEL_ERROR, 1.0 + MODEL_ERROR),
        'noise_seed': int(rng.integers(0, 2 ** 31)),
        'stalls': _stalls(rng, duration),
        'start_mode': start,
    }


def _stalls(rng, duration):
    """Input stalls of a run: STALL_RATE a second on average (Poisson), each at a uniform time
    and STALL_MS long (whole ms, uniform), as (start s, length s) pairs in time order.
    """
    count = int(rng.poisson(STALL_RATE * duration))
    starts = np.sort(rng.uniform(0.0, duration, count))
    lengths = rng.integers(STALL_MS[0], STALL_MS[1] + 1, count) / 1000.0
    return [(float(a), float(b)) for a, b in zip(starts, lengths)]


def _floats(a):
    return [float(x) for x in np.ravel(a)]


def unmodelled_moment(plant, disturbance_max=DISTURBANCE_MAX):
    """The most the campaign's runs ask the controller to hold before learning it (N m): the
    largest disturbance plus the gravity moment of the largest error in m rho (mass and
    centre-of-mass height each off by 20 %: 1.2^2 - 1 = 44 %) at the largest tilt at the goal;
    plant: the nominal testbed's PlantConfig.
    """
    m_rho = plant.mass * float(np.linalg.norm(plant.cog_offset))
    return float(disturbance_max + ((1.0 + MODEL_ERROR) ** 2 - 1.0) * m_rho
                 * float(np.linalg.norm(plant.gravity))
                 * math.sin(math.radians(TILT_DEG)))


class Manoeuvres:
    """The runs of campaigns on one testbed (base: a parameter file's sections): ``sections(seed,
    index)`` is run index of seed as a scenario file's sections, with ``gains`` (controller
    parameters) put over the testbed's. The manoeuvre does not depend on the gains: the goal is
    the one the testbed's own controller accepts, so every gain set of a study flies the same runs.
    """

    def __init__(self, base, duration=20.0, disturbance_max=DISTURBANCE_MAX, stratum='all'):
        self.base, self.duration, self.disturbance_max = base, float(duration), disturbance_max
        self.stratum = stratum
        self.nominal_c = resolve(CONTROLLER, node_overrides(base, CONTROLLER))
        self.nominal = testbed_setup(resolve(SIM, node_overrides(base, SIM))).plant
        self.sensor_axis = controller_config(self.nominal_c).cones.r
        self.tilt_max_deg = math.degrees(self.nominal.tilt_max)
        self.unmodelled = unmodelled_moment(self.nominal, disturbance_max)
        self._probes = {}

    def goal_ok(self, cones, R_d, gains=None):     # the controller's own set-point check
        key = tuple(sorted((gains or {}).items()))
        if key not in self._probes:
            self._probes[key] = AttitudeController(controller_config(dict(
                self.nominal_c, unmodelled_moment_max=self.unmodelled, **(gains or {}))))
        # the gains too: the barrier's own parameters (alpha, the guard) shape the cones
        values = dict(self.nominal_c, **(gains or {}))
        values.update(cone_values(cones))
        return self._probes[key].setpoint_problem(R_d, cone_set(values)) is None

    def goal_refused(self, sections):
        """Whether the run's goal is one its gain set's controller refuses (see ``sections``)."""
        return self.unmodelled > 0.0 and not goal_check(sections)

    def sections(self, seed, index, gains=None):
        """The scenario file's sections ({'/**' or node: flat parameters}) of run index.

        A goal that the gain set's controller refuses (its barrier cannot hold the unmodelled
        moment there: ``unmodelled_moment_max``, a check that is not part of the control law) is
        flown all the same, with the check off (0), so that every gain set flies every run;
        ``goal_refused`` tells.
        """
        m = draw_manoeuvre(seed, index, self.sensor_axis, self.goal_ok,
                           self.duration, self.stratum, self.tilt_max_deg)
        return self.sections_of(m, 'campaign seed %d, run %d' % (seed, index), gains)

    def sections_of(self, m, title, gains=None):
        """The scenario file's sections of a manoeuvre m (``draw_manoeuvre``'s dict, drawn or
        chosen: the falsifier's), titled title, with gains over the testbed's (see ``sections``).
        """
        base = self.base
        controller = {k: v for k, v in base.get('controller', {}).items()
                      if not k.startswith(('cones.', 'setpoint'))}
        controller['unmodelled_moment_max'] = self.unmodelled
        controller.update(gains or {})
        controller.update(cone_values(m['cones']))
        controller['setpoint'] = _floats(so3.rot_to_quat(m['R_d']))
        controller['arming_setpoint'] = 'configured'     # an experiment, on the nodes too
        if gains and not self.goal_ok(m['cones'], m['R_d'], gains):
            controller['unmodelled_moment_max'] = 0.0
        S = np.diag(np.sqrt(m['inertia_factors']))
        J = self.nominal.inertia
        E = S @ (0.5 * np.trace(J) * np.eye(3) - J) @ S            # second moment of the mass
        rho = self.nominal.cog_offset
        sim = dict(base.get('sim', {}))
        sim.update({
            'initial_attitude': _floats(so3.rot_to_quat(m['R0'])),
            'mass': float(self.nominal.mass * m['mass_factor']),
            'inertia': _floats(np.trace(E) * np.eye(3) - E),
            'cog_offset': _floats(rho * m['cog_factor']),
            'disturbance.constant': _floats(m['disturbance'] * self.disturbance_max),
            'noise.seed': m['noise_seed'],
        })
        scenario = {'title': title, 'duration': self.duration,
                    'latency': m['latency_ms'] / 1000.0,
                    'stalls.start': [a for a, _ in m['stalls']],
                    'stalls.duration': [b for _, b in m['stalls']]}
        if m.get('start_mode', 'held') != 'held':
            scenario['start'] = m['start_mode']
        if m.get('jitter_ms'):                  # (the falsifier's: steps up to this late)
            scenario['tick_jitter'] = m['jitter_ms'] / 1000.0
            scenario['tick_jitter_seed'] = m.get('jitter_seed', m['noise_seed'])
        return {'/**': dict(base.get('/**', {})), 'controller': controller, 'sim': sim,
                'scenario': scenario}


def run_sections(base, seed, index, duration=20.0, disturbance_max=DISTURBANCE_MAX):
    """The scenario file's sections of run index (one run of ``Manoeuvres``)."""
    return Manoeuvres(base, duration, disturbance_max).sections(seed, index)


def write_scenario_file(sections, path):
    """Write sections as a ROS 2 parameter file (nested keys, floats exact)."""
    name = os.path.basename(path)
    write_parameter_file(sections, path, 'Written by `campaign`; fly it again with `campaign '
                         '--replay %s` or `scenario %s --out DIR`.' % (name, name))


# --- flying -----------------------------------------------------------------------------------

