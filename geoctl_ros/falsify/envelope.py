"""The falsifier's search space: the envelope a manoeuvre may be drawn from, as coordinates in a
box, and the map from a point of the box to a scenario (``Space.manoeuvre``).

A point sets what the campaign draws at random (``geoctl_ros.campaign.manoeuvres``), each within
the campaign's own range, so that "inside the envelope" means the same for both:

- the cones: the first (half-angle 10-35 deg, its axis at an azimuth and within +-20 deg of the
  horizon) and, with ``cones`` > 1, the others likewise;
- the manoeuvre: the sensor starts 5-30 deg outside the first cone at an azimuth round its axis,
  and its goal is 5-30 deg outside it on the far side (150-210 deg further round); each attitude
  the most upright one, turned about the sensor axis by up to +-15 deg;
- the inputs: the measurement latency (whole ms), the control steps' lateness (tick jitter, in
  steps of ``JITTER_STEP_MS``: the runs of a batch share their late steps, so each jitter is a
  batch of its own, and few of them keep the batches large) and ``stalls`` input stalls, each
  at any time of the run (at the approach to a cone too) and 10-40 ms long (whole ms);
- the model's errors: the true mass, the inertia's stretch along each body axis and the centre of
  mass, each off by up to ``model_error``; a constant disturbance of any direction up to
  ``disturbance_max``;
- the sensors' noise: its seed (a whole number), so the search can choose the noise too (the
  late steps keep a seed of their own, ``JITTER_SEED``, so that runs batch by their jitter).

A point whose manoeuvre is outside the campaign's rules (cones closer than 10 deg edge to edge,
a start or goal within 5 deg of a cone, a straight way that misses the first cone, a body tilted
past the joint's 40 deg, or a goal that the controller refuses) is outside the envelope: it is
not flown, and its robustness is ``OUTSIDE`` (no counterexample).
"""
from dataclasses import dataclass
import math
from typing import Dict, List, Optional, Tuple

import numpy as np

from geoctl_ros.campaign import manoeuvres
from geoctl_ros.campaign.manoeuvres import (
    CLEAR_DEG,
    CONE_ELEVATION_DEG,
    DISTURBANCE_MAX,
    GAP_DEG,
    MODEL_ERROR,
    STALL_MS,
    TWIST_DEG,
    angle_deg,
    upright,
)
from geoctl_ros.core.geometry import sphere

OUTSIDE = 180.0          # the robustness of a point outside the envelope (deg: above any real)
NOISE_SEEDS = 1_000_000  # the sensors' noise: a coordinate, its seed a whole number below this
JITTER_SEED = 1          # the late steps' seed (runs fly together only with the same late steps)
JITTER_STEP_MS = 5.0     # the tick jitter in steps of this (runs fly together only with the same)


@dataclass(frozen=True)
class Envelope:
    """The ranges a falsification searches (the documented envelope by default)."""

    latency_ms_max: float = 60.0
    jitter_ms_max: float = 10.0
    stalls: int = 2
    cones: int = 2
    model_error: float = MODEL_ERROR
    disturbance_max: float = DISTURBANCE_MAX
    duration: float = 12.0       # s a run flies (the settle requirement looks 10 s ahead)


def coordinates(env: Envelope) -> List[Tuple[str, float, float]]:
    """The box: (name, low, high) per coordinate, in the order of a point's entries."""
    box = [('cone1_half_angle_deg', 10.0, 35.0), ('cone1_azimuth_deg', 0.0, 360.0),
           ('cone1_elevation_deg', -CONE_ELEVATION_DEG, CONE_ELEVATION_DEG),
           ('start_offset_deg', CLEAR_DEG, 30.0), ('start_azimuth_deg', 0.0, 360.0),
           ('goal_offset_deg', CLEAR_DEG, 30.0), ('goal_turn_deg', 150.0, 210.0),
           ('start_twist_deg', -TWIST_DEG, TWIST_DEG), ('goal_twist_deg', -TWIST_DEG, TWIST_DEG)]
    for k in range(2, env.cones + 1):
        box += [('cone%d_half_angle_deg' % k, 10.0, 35.0), ('cone%d_azimuth_deg' % k, 0.0, 360.0),
                ('cone%d_elevation_deg' % k, -CONE_ELEVATION_DEG, CONE_ELEVATION_DEG)]
    box += [('latency_ms', 0.0, env.latency_ms_max), ('jitter_ms', 0.0, env.jitter_ms_max)]
    for k in range(1, env.stalls + 1):
        box += [('stall%d_start_s' % k, 0.0, env.duration),
                ('stall%d_ms' % k, float(STALL_MS[0]), float(STALL_MS[1]))]
    e = env.model_error
    box += [('mass_factor', 1.0 - e, 1.0 + e), ('inertia_x_factor', 1.0 - e, 1.0 + e),
            ('inertia_y_factor', 1.0 - e, 1.0 + e), ('inertia_z_factor', 1.0 - e, 1.0 + e),
            ('cog_factor', 1.0 - e, 1.0 + e),
            ('disturbance_azimuth_deg', 0.0, 360.0), ('disturbance_elevation_deg', -90.0, 90.0),
            ('disturbance_share', 0.0, 1.0), ('noise_seed', 0.0, float(NOISE_SEEDS))]
    return box


def _axis(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


class Space:
    """The envelope's box over a testbed (base: a parameter file's sections, with the gains to
    falsify): ``manoeuvre(x)`` and ``sections(x)``.
    """

    def __init__(self, base: dict, env: Envelope):
        self.env = env
        self.box = coordinates(env)
        self.names = [name for name, _, _ in self.box]
        self.low = np.array([lo for _, lo, _ in self.box])
        self.high = np.array([hi for _, _, hi in self.box])
        # the campaign's runs of this testbed, with the envelope's disturbance (the goal check)
        self.draw = manoeuvres.Manoeuvres(base, env.duration, env.disturbance_max)

    def point(self, x) -> Dict[str, float]:
        """x (in the box's order) as {name: value}, whole ms rounded."""
        p = dict(zip(self.names, (float(v) for v in x)))
        for name in p:
            if name.endswith('_ms'):
                p[name] = float(round(p[name]))
        p['jitter_ms'] = JITTER_STEP_MS * round(p['jitter_ms'] / JITTER_STEP_MS)
        return p

    def manoeuvre(self, x) -> Optional[dict]:
        """The manoeuvre of point x (``draw_manoeuvre``'s dict), or None outside the envelope."""
        p = self.point(np.clip(np.asarray(x, dtype=float), self.low, self.high))
        cones = [(_axis(p['cone%d_azimuth_deg' % k], p['cone%d_elevation_deg' % k]),
                  p['cone%d_half_angle_deg' % k]) for k in range(1, self.env.cones + 1)]
        for i, (v, t) in enumerate(cones):
            for w, s in cones[i + 1:]:
                if angle_deg(v, w) < t + s + GAP_DEG:
                    return None
        v0, th0 = cones[0][0], math.radians(cones[0][1])
        azimuth = math.radians(p['start_azimuth_deg'])
        d0 = sphere.direction(v0, th0 + math.radians(p['start_offset_deg']), azimuth)
        d1 = sphere.direction(v0, th0 + math.radians(p['goal_offset_deg']),
                              azimuth + math.radians(p['goal_turn_deg']))
        if any(angle_deg(d, v) < t + CLEAR_DEG for d in (d0, d1) for v, t in cones):
            return None
        if not manoeuvres.crosses(d0, d1, v0, cones[0][1]):
            return None
        r = sphere.unit(np.asarray(self.draw.sensor_axis, dtype=float))
        R0 = upright(r, d0, p['start_twist_deg'])
        R_d = upright(r, d1, p['goal_twist_deg'])
        listed = [(list(map(float, v)), float(t)) for v, t in cones]
        if R0 is None or R_d is None or not self.draw.goal_ok(listed, R_d):
            return None
        stalls = sorted((p['stall%d_start_s' % k], p['stall%d_ms' % k] / 1000.0)
                        for k in range(1, self.env.stalls + 1))
        return {
            'cones': listed, 'R0': R0, 'R_d': R_d,
            'latency_ms': int(p['latency_ms']), 'jitter_ms': int(p['jitter_ms']),
            'jitter_seed': JITTER_SEED,
            'disturbance': p['disturbance_share'] * _axis(p['disturbance_azimuth_deg'],
                                                          p['disturbance_elevation_deg']),
            'mass_factor': p['mass_factor'],
            'inertia_factors': np.array([p['inertia_x_factor'], p['inertia_y_factor'],
                                         p['inertia_z_factor']]),
            'cog_factor': p['cog_factor'],
            'noise_seed': min(int(p['noise_seed']), NOISE_SEEDS - 1), 'stalls': stalls,
        }

    def sections(self, x, title: str) -> Optional[dict]:
        """The scenario file's sections of point x, or None outside the envelope."""
        m = self.manoeuvre(x)
        return None if m is None else self.draw.sections_of(m, title)

