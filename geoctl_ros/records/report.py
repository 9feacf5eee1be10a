"""A recorded flight as the paper's figures and a summary (the ``report`` command,
``geoctl_ros.cli.report``, says what it reads and writes): the bag read back as series, the
cones from the bag or a parameter file, the summary's figures, and the headless replay of the
flight for ``--compare``.
"""
import math
import os
from typing import NamedTuple

import numpy as np
import yaml

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.telemetry.diagnostics import NAME as CONTROLLER_STATUS
from geoctl_ros.core.telemetry.diagnostics import from_values, state_kind
from geoctl_ros.core.telemetry.stats import settle_time
from geoctl_ros.params import (
    CONTROLLER,
    SCENARIO,
    SIM,
    cone_set,
    load_parameter_file,
    node_overrides,
    resolve,
)
from geoctl_ros.params.topics import BY_NAME, CONTROLLER_PARAMETERS, TOPICS
from geoctl_ros.records import bag
from geoctl_ros.records.fields import quaternion, vector
from geoctl_ros.sim import scenario


class Flight(NamedTuple):
    """A recorded flight as time series (t in s since the bag's first message)."""

    cones: object                  # core.law.cones.ConeSet, or None
    attitude_source: str           # '/sim/true_pose', '/attitude', '/pose' or ''
    attitude_t: np.ndarray
    rotations: np.ndarray          # (N, 3, 3)
    sensor_path: np.ndarray        # (N, 3): R r
    cone_angles: np.ndarray        # (N, cones) deg
    psi: tuple
    e_R: tuple
    e_Omega: tuple
    delta_bar: tuple
    motors: tuple
    diag_t: np.ndarray
    armed: np.ndarray
    pose_age_ms: np.ndarray
    imu_age_ms: np.ndarray
    failsafe_t: list
    states: list                   # (t, state kind) of the controller's diagnostics
    last_figures: object           # the last diagnostics' Figures, or None
    missing: list                  # the package's topics the bag lacks
    setpoints: list                # (t, quaternion) of active_setpoint, as the controller flew


def _commands(m):
    """A motor_commands message's normalised commands: a JointState's effort (in a record of
    an earlier version, a Float64MultiArray's data).
    """
    return list(m.effort) if hasattr(m, 'effort') else list(m.data)


def _series(msgs, t0, value):
    if not msgs:
        return np.zeros(0), np.zeros((0,))
    return (np.array([m.t - t0 for m in msgs]),
            np.array([value(m.msg) for m in msgs], dtype=float))


def _cones_of(stored, params_file):
    if params_file:
        values = node_overrides(load_parameter_file(params_file), CONTROLLER)
    elif stored:
        values = yaml.safe_load(stored[-1].msg.data)
    else:
        return None
    return cone_set(resolve(CONTROLLER, values))


def load_flight(path, params_file=None):
    """The Flight recorded in the bag at path; raises ValueError (not a bag) or ConfigError."""
    topics = bag.by_package_names(bag.read_bag(path))
    present = {k for k, v in topics.items() if v}
    if not present & set(BY_NAME):
        raise ValueError('%s has none of the topics geoctl_ros publishes (it has %s)' % (
            path, ', '.join(sorted(present)) or 'no messages'))
    first = [v[0].t for v in topics.values() if v]
    t0 = min(first) if first else 0.0
    cones = _cones_of(topics.get(CONTROLLER_PARAMETERS.name), params_file)
    # the truth where the sim gives it, else the controller's measured attitude in the package's
    # frames, else the raw pose (a record from before /attitude: its conventions the package's)
    source = next((s for s in ('/sim/true_pose', '/attitude', '/pose') if s in present), '')
    att = topics.get(source, [])
    att_t = np.array([m.t - t0 for m in att])
    Rs = (np.array([so3.quat_to_rot(quaternion(
        m.msg.quaternion if source == '/attitude' else m.msg.pose.orientation)) for m in att])
        if att else np.zeros((0, 3, 3)))
    if cones is not None and att:
        path_ = Rs @ cones.r
        angles = np.array([cones.angles_deg(R) for R in Rs]).reshape(len(Rs), len(cones))
    else:
        path_, angles = np.zeros((0, 3)), np.zeros((0, 0))
    statuses = [(m.t - t0, s) for m in topics.get('/diagnostics', [])
                for s in m.msg.status if s.name == CONTROLLER_STATUS]
    figures = [(t, s.level, s.message, from_values((kv.key, kv.value) for kv in s.values))
               for t, s in statuses]
    failsafe_t, previous = [], False
    for t, _, _, fig in figures:
        if fig.failsafe and not previous:
            failsafe_t.append(t)
        previous = fig.failsafe

    def vec3(m):
        return vector(m.vector)
    return Flight(
        cones=cones, attitude_source=source, attitude_t=att_t, rotations=Rs, sensor_path=path_,
        cone_angles=angles,
        psi=_series(topics.get('/configuration_error', []), t0, lambda m: m.data),
        e_R=_series(topics.get('/attitude_error', []), t0, vec3),
        e_Omega=_series(topics.get('/angular_velocity_error', []), t0, vec3),
        delta_bar=_series(topics.get('/disturbance_estimate', []), t0, lambda m: list(m.data)),
        motors=_series(topics.get('/motor_commands', []), t0, _commands),
        diag_t=np.array([t for t, *_ in figures]),
        armed=np.array([float(f.armed) for *_, f in figures]),
        pose_age_ms=np.array([1e3 * f.pose_age if math.isfinite(f.pose_age) else np.nan
                              for *_, f in figures]),
        imu_age_ms=np.array([1e3 * f.imu_age if math.isfinite(f.imu_age) else np.nan
                             for *_, f in figures]),
        failsafe_t=failsafe_t,
        states=[(t, state_kind(f)) for t, *_, f in figures],
        last_figures=figures[-1][3] if figures else None,
        missing=[t.name for t in TOPICS if t.name not in present],
        setpoints=[(m.t - t0, quaternion(m.msg.quaternion))
                   for m in topics.get('/active_setpoint', [])])


def armed_span(f):
    """(first armed time, the first disarmed report after the last armed one, or the record's
    end) from the controller's diagnostics, or None when it was never armed.
    """
    armed = np.nonzero(f.armed > 0)[0]
    if not len(armed):
        return None
    end = (f.diag_t[armed[-1] + 1] if armed[-1] + 1 < len(f.diag_t)
           else max([f.diag_t[-1]] + list(f.attitude_t[-1:])))
    return float(f.diag_t[armed[0]]), float(end)


def summary(f):
    """The flight's figures: closest approach per cone, time in each state, settle time, final
    error, failsafes and gaps ridden through.
    """
    out = {'attitude_source': f.attitude_source or None, 'missing_topics': f.missing}
    if f.cones is not None and len(f.attitude_t):
        theta = np.degrees(f.cones.theta)
        out['closest_approach_deg'] = {
            n: {'angle': float(f.cone_angles[:, i].min()), 'half_angle': float(theta[i]),
                'margin': float(f.cone_angles[:, i].min() - theta[i]),
                't': float(f.attitude_t[np.argmin(f.cone_angles[:, i])])}
            for i, n in enumerate(f.cones.names)}
    # the final figures are the armed flight's (after a disarm the testbed is on its own)
    span = armed_span(f)
    out['armed_s'] = None if span is None else list(span)
    t_from, t_to = (-np.inf, np.inf) if span is None else span
    t_psi, psi = f.psi
    keep = (t_psi >= t_from) & (t_psi <= t_to)
    t_psi, psi = t_psi[keep], psi[keep]
    out['final_psi'] = float(psi[-1]) if len(psi) else None
    settle = settle_time(t_psi, psi) if len(psi) else None
    out['settle_time_s'] = (None if settle is None else
                            settle - (t_from if np.isfinite(t_from) else 0.0))
    t_eR, e_R = f.e_R
    e_R = e_R[(t_eR >= t_from) & (t_eR <= t_to)]
    out['final_eR_norm'] = float(np.linalg.norm(e_R[-1])) if len(e_R) else None
    durations = {}
    for (t, kind), (t_next, _) in zip(f.states, f.states[1:]):
        durations[kind] = durations.get(kind, 0.0) + (t_next - t)
    out['time_in_state_s'] = {k: round(v, 3) for k, v in durations.items()}
    out['failsafes'] = len(f.failsafe_t)
    last = f.last_figures
    out['gaps_ridden'] = (None if last is None else
                          {'pose': last.pose_gaps.ridden, 'imu': last.imu_gaps.ridden})
    out['duration_s'] = float(max([0.0] + [s[0][-1] for s in (f.psi, f.motors) if len(s[0])]
                                  + list(f.attitude_t[-1:])))
    return out


def compare_sections(f, scenario_file):
    """The scenario file's sections, flown from the record's state at arming: the sim starts at
    the recorded attitude, and the controller flies the set points the record shows, at their
    times after arming, for as long as the record was armed. Raises ValueError when the record
    has no armed span or no attitude.
    """
    span = armed_span(f)
    if span is None or not len(f.attitude_t):
        raise ValueError('the record was never armed, or has no attitude: nothing to compare')
    t_arm, t_end = span
    sections = load_parameter_file(scenario_file)
    sim = sections.setdefault(SIM, {})
    ctl = sections.setdefault(CONTROLLER, {})
    k = int(np.searchsorted(f.attitude_t, t_arm))
    sim['initial_attitude'] = [float(v) for v in so3.rot_to_quat(
        f.rotations[min(k, len(f.rotations) - 1)])]
    sim['initial_angular_velocity'] = [0.0, 0.0, 0.0]
    before = [q for t, q in f.setpoints if t <= t_arm]
    after = [(t - t_arm, q) for t, q in f.setpoints if t_arm < t <= t_end]
    first = before[-1] if before else (after[0][1] if after else None)
    for key in [k for k in ctl if k.startswith('setpoint_schedule.')]:
        del ctl[key]
    if first is not None:
        ctl['setpoint'] = [float(v) for v in first]
    if after:
        ctl['setpoint_schedule.times'] = [0.0] + [float(t) for t, _ in after]
        ctl['setpoint_schedule.quaternions'] = [float(v) for q in [first] + [q for _, q in after]
                                                for v in q]
    sections.setdefault(SCENARIO, {})['duration'] = round(t_end - t_arm, 3)
    return sections, t_arm


def fly_headless(f, scenario_file):
    """(scenario Result, the record's arming time) of compare_sections' run."""
    sections, t_arm = compare_sections(f, scenario_file)
    return scenario.run(scenario.from_sections(sections, 'headless')), t_arm


def markdown(path, s):
    lines = ['# Flight %s' % os.path.basename(os.path.normpath(path)), '',
             '| figure | value |', '|---|---|', '| duration | %.1f s |' % s['duration_s']]
    for n, c in (s.get('closest_approach_deg') or {}).items():
        lines.append('| closest approach, cone %s | %.2f deg (half-angle %.1f): margin %.2f deg '
                     'at %.1f s |' % (n, c['angle'], c['half_angle'], c['margin'], c['t']))
    lines.append('| attitude from | %s |' % (s['attitude_source'] or '-'))
    lines.append('| armed | %s |' % ('never' if s['armed_s'] is None else
                                      'from %.1f s to %.1f s' % tuple(s['armed_s'])))
    fmt = {'final_psi': '%.3g (armed)', 'settle_time_s': '%.1f s after arming',
           'final_eR_norm': '%.3g (armed)'}
    for k, f in fmt.items():
        lines.append('| %s | %s |' % (k, '-' if s[k] is None else f % s[k]))
    lines.append('| time in each state | %s |' % (', '.join(
        '%s %.1f s' % kv for kv in s['time_in_state_s'].items()) or '-'))
    lines.append('| failsafes | %d |' % s['failsafes'])
    g = s['gaps_ridden']
    lines.append('| gaps ridden through | %s |' % ('-' if g is None else
                                                  'pose %d, imu %d' % (g['pose'], g['imu'])))
    h = s.get('headless')
    if h:
        lines.append('| headless (%s), closest approach | %s |' % (
            os.path.basename(h['scenario']), ', '.join(
                '%s %.2f deg' % kv for kv in h['closest_approach_deg'].items())))
    if s['missing_topics']:
        lines.append('| not in the bag | %s |' % ', '.join(s['missing_topics']))
    return '\n'.join(lines) + '\n'
