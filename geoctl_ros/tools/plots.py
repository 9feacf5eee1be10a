"""Every figure the tools draw, in one place: a scenario run's after the paper's Figs. 2, 3 and 5,
a campaign's, and a sim-in-the-loop flight's. Each is a matplotlib Figure of its own written to a
PNG (no pyplot state, so no display and no backend are needed).
"""
import math
import os

from matplotlib.figure import Figure
import numpy as np

from geoctl_ros.core import so3
from geoctl_ros.params import cone_set
from geoctl_ros.tools import manoeuvres


def _subplots(*grid, figsize, **kw):
    """(figure, axes) like pyplot.subplots, on a Figure of its own."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*grid, **kw)


def _col(result, name):
    return result.history[:, result.columns.index(name)]


def _cols(result, prefix):
    return [c for c in result.columns if c.startswith(prefix)]


def scenario_figures(result, out_dir):
    """Write attitude_error.png, psi.png, cone_angles.png, disturbance.png, control_moment.png,
    motor_commands.png (rotor actuation only) and sensor_path.png; returns their paths.
    """
    title = result.summary.get('title') or result.scenario.name
    t = _col(result, 't')
    paths = []

    def save(fig, name):
        fig.suptitle(title, fontsize=10)
        fig.tight_layout()
        path = os.path.join(out_dir, name)
        fig.savefig(path, dpi=110)
        paths.append(path)

    fig, ax = _subplots(figsize=(7, 3.5))
    for i, c in enumerate(('eR_x', 'eR_y', 'eR_z')):
        ax.plot(t, _col(result, c), label='$e_{R,%d}$' % (i + 1))
    ax.set(xlabel='t [s]', ylabel='$e_R$', title='attitude error vector')
    ax.grid(True, alpha=0.3)
    ax.legend()
    save(fig, 'attitude_error.png')

    fig, ax = _subplots(figsize=(7, 3.5))
    ax.plot(t, _col(result, 'psi'))
    ax.set(xlabel='t [s]', ylabel=r'$\Psi$', title=r'configuration error $\Psi$')
    ax.grid(True, alpha=0.3)
    save(fig, 'psi.png')

    fig, ax = _subplots(figsize=(7, 3.5))
    theta = result.summary['cone_half_angle_deg']
    for i, c in enumerate(_cols(result, 'angle_')):
        name = c[len('angle_'):]
        line, = ax.plot(t, _col(result, c), label=name)
        ax.axhline(theta[name], color=line.get_color(), ls='--', lw=1)
    ax.set(xlabel='t [s]', ylabel='angle [deg]',
           title=r'angle between $Rr$ and each cone axis (dashed: half-angle)')
    ax.grid(True, alpha=0.3)
    if theta:
        ax.legend()
    save(fig, 'cone_angles.png')

    fig, ax = _subplots(figsize=(7, 3.5))
    for i, c in enumerate(_cols(result, 'dbar_')):
        line, = ax.plot(t, _col(result, c), label=r'$\bar\Delta_{%d}$' % (i + 1))
        ax.plot(t, _col(result, 'dtrue_%d' % i), color=line.get_color(), ls='--', lw=1)
    ax.set(xlabel='t [s]', ylabel='estimate', title=r'disturbance estimate $\bar\Delta$ '
           '(dashed: true unmodelled disturbance)')
    ax.grid(True, alpha=0.3)
    ax.legend(ncol=2)
    save(fig, 'disturbance.png')

    fig, ax = _subplots(figsize=(7, 3.5))
    for c in ('u_x', 'u_y', 'u_z'):
        ax.plot(t, _col(result, c), label=c)
    ax.set(xlabel='t [s]', ylabel='moment [N m]', title='control moment u about the pivot')
    ax.grid(True, alpha=0.3)
    ax.legend()
    save(fig, 'control_moment.png')

    cmd_cols = _cols(result, 'cmd_')
    if cmd_cols:
        fig, (ax1, ax2) = _subplots(2, 1, figsize=(7, 5.5), sharex=True)
        for c in cmd_cols:
            ax1.plot(t, _col(result, c), lw=1, label='motor %s' % c[len('cmd_'):])
        ax1.set(ylabel='ESC command', title='motor commands (integer, 0..command_max)')
        ax1.grid(True, alpha=0.3)
        ax1.legend(ncol=3, fontsize=8)
        for c in _cols(result, 'thrust_'):
            ax2.plot(t, _col(result, c), lw=1)
        ax2.set(xlabel='t [s]', ylabel='thrust [N]', title='rotor thrusts (after the motor lag)')
        ax2.grid(True, alpha=0.3)
        save(fig, 'motor_commands.png')

    fig = Figure(figsize=(6, 6))
    ax = fig.add_subplot(projection='3d')
    cones = cone_set(result.scenario.controller)
    q = result.history[:, [result.columns.index(c) for c in ('qx', 'qy', 'qz', 'qw')]]
    sphere_path(ax, np.array([so3.quat_to_rot(qi) @ cones.r for qi in q]), cones)
    save(fig, 'sensor_path.png')
    return paths


def sphere_path(ax, path, cones):
    """The sensor axis R r (path: (N, 3), world frame) on the unit sphere, with the cones drawn
    in red.
    """
    u, v = np.mgrid[0:2 * np.pi:40j, 0:np.pi:20j]
    ax.plot_wireframe(np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v), color='0.85',
                      lw=0.4)
    for axis, theta in zip(cones.V, cones.theta):
        # cone surface from the centre to the sphere
        a = axis / np.linalg.norm(axis)
        p = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        p /= np.linalg.norm(p)
        q2 = np.cross(a, p)
        phi = np.linspace(0, 2 * np.pi, 60)
        rim = (np.cos(theta) * a[None, :] + np.sin(theta) * (np.cos(phi)[:, None] * p
                                                              + np.sin(phi)[:, None] * q2))
        s = np.linspace(0, 1, 2)
        X = s[:, None, None] * rim[None, :, :]
        ax.plot_surface(X[..., 0], X[..., 1], X[..., 2], color='red', alpha=0.35, lw=0)
        ax.plot(rim[:, 0], rim[:, 1], rim[:, 2], color='darkred', lw=1)
    ax.plot(path[:, 0], path[:, 1], path[:, 2], color='blue', lw=1.5, label='$Rr$')
    ax.scatter(*path[0], color='green', marker='o', s=40, label='start')
    ax.scatter(*path[-1], color='green', marker='x', s=60, label='end')
    ax.set(xlabel='x', ylabel='y', zlabel='z', xlim=(-1, 1), ylim=(-1, 1), zlim=(-1, 1),
           title='sensor axis on the unit sphere (world frame)')
    ax.set_box_aspect((1, 1, 1))
    ax.legend(loc='upper left')


def closest_approach_figure(closest_deg, path):
    """A campaign's histogram of the closest approach per run."""
    fig, ax = _subplots(figsize=(7, 3.5))
    ax.hist(closest_deg, bins=40, color='tab:blue', alpha=0.8)
    ax.axvline(0.0, color='tab:red', lw=1.5, label='cone boundary')
    ax.set(xlabel='closest approach to a cone [deg] (negative: inside)', ylabel='runs',
           title='%d runs: closest approach of the sensor to any cone' % len(closest_deg))
    ax.legend()
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def worst_runs_figure(flown, path):
    """A campaign's worst runs ([(name, margin at each control step, sensor direction at each,
    dt, controller parameters)]): cone margin in time, and the worst one's sensor path.
    """
    fig, (a1, a2) = _subplots(1, 2, figsize=(11, 4))
    for name, margins, _, dt, _ in flown:
        a1.plot(np.arange(len(margins)) * dt, margins, lw=1, label=name)
    a1.axhline(0.0, color='k', lw=0.8)
    a1.set(xlabel='t [s]', ylabel='cone margin [deg]', title='the %d worst runs' % len(flown))
    a1.legend(fontsize=7)
    a1.grid(True, alpha=0.3)
    name, _, sensor, _, controller = flown[0]
    _sky(a2, sensor.astype(float), controller, '%s: sensor path' % name)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def gain_study_figure(figures, labels, front, path):
    """A gain study: each gain set's closest approach (p1) against its median settle time, the
    non-dominated sets marked (``geoctl_ros.tools.study``).
    """
    fig, ax = _subplots(figsize=(8, 5))
    settle = np.array([f['settle_median_s'] for f in figures])
    finite = settle[np.isfinite(settle)]
    cap = (finite.max() * 1.1) if len(finite) else 1.0
    x = np.where(np.isfinite(settle), settle, cap)
    y = np.array([f['closest_p1_deg'] for f in figures])
    bad = np.array([f['violations'] > 0 for f in figures])
    on = np.isin(np.arange(len(figures)), front)
    ax.scatter(x[~on & ~bad], y[~on & ~bad], color='tab:gray', label='dominated')
    ax.scatter(x[bad], y[bad], color='tab:red', marker='x', label='with violations')
    order = [k for k in np.argsort(x) if on[k]]
    ax.plot(x[order], y[order], 'o-', color='tab:green', label='non-dominated')
    for k, text in enumerate(labels):
        ax.annotate('%d: %s' % (k + 1, text), (x[k], y[k]), fontsize=7,
                    textcoords='offset points', xytext=(4, 4))
    if not np.all(np.isfinite(settle)):
        ax.axvline(cap, color='k', lw=0.8, ls=':', label='median not settled (drawn here)')
    ax.set(xlabel='median settle time [s] (attitude error < 5 deg from then on)',
           ylabel='closest approach, 1st percentile [deg]',
           title='gain study: %d gain sets, %d runs each' % (len(figures), figures[0]['runs']))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _sky(ax, path, controller, title):
    """The sensor's world direction in azimuth / elevation, with the cones' boundaries."""
    def az_el(d):
        d = np.atleast_2d(d)
        return (np.degrees(np.arctan2(d[:, 1], d[:, 0])),
                np.degrees(np.arcsin(np.clip(d[:, 2], -1, 1))))
    for name in controller['cones.names']:
        v = manoeuvres.unit(np.asarray(controller['cones.%s.axis' % name], dtype=float))
        th = math.radians(controller['cones.%s.half_angle_deg' % name])
        ring = np.array([manoeuvres.direction(v, th, a)
                         for a in np.linspace(0, 2 * math.pi, 181)])
        az, el = az_el(ring)
        ax.plot(az, el, '.', ms=1.5, color='tab:red')
    az, el = az_el(path)
    ax.plot(az, el, '.', ms=1.5, color='tab:blue')
    ax.plot(az[0], el[0], 'o', color='tab:green', label='start')
    ax.plot(az[-1], el[-1], 's', color='k', label='end')
    ax.set(xlabel='azimuth [deg]', ylabel='elevation [deg]', title=title, xlim=(-180, 180),
           ylim=(-90, 90))
    ax.legend(fontsize=7)
    ax.grid(True, alpha=0.3)


def sil_figure(out, t, angles, cones, err, psi, cmd_t, commands):
    """sil.png: a sim-in-the-loop flight as recorded over DDS (``geoctl_ros.tools.demo``)."""
    fig, axs = _subplots(2, 2, figsize=(11, 7))
    ax = axs[0, 0]
    for i, name in enumerate(cones.names):
        line, = ax.plot(t, angles[:, i], label=name)
        ax.axhline(math.degrees(cones.theta[i]), color=line.get_color(), ls='--', lw=1)
    ax.set(xlabel='t since arming [s]', ylabel='deg',
           title='true angle to each cone (dashed: limit)')
    ax.legend()
    ax = axs[0, 1]
    ax.plot(t, err)
    ax.set(xlabel='t since arming [s]', ylabel='deg',
           title='true attitude error to the final set point')
    ax = axs[1, 0]
    if psi:
        ax.semilogy([p[0] for p in psi], [max(p[1], 1e-12) for p in psi])
    ax.set(xlabel='t since arming [s]', ylabel='Psi', title='configuration error (as published)')
    ax = axs[1, 1]
    if len(commands):
        ax.plot(cmd_t, commands, lw=0.8)
    ax.set(xlabel='t since arming [s]', ylabel='normalised command',
           title='motor_commands (as received)')
    for a in axs.flat:
        a.grid(True, alpha=0.3)
    fig.suptitle('sim-in-the-loop over DDS: controller and sim as separate processes')
    fig.tight_layout()
    fig.savefig(os.path.join(out, 'sil.png'), dpi=100)


def flight_figures(f, out_dir):
    """The figures of a recorded flight (``geoctl_ros.tools.report``): sensor_path.png (the
    sensor axis on the unit sphere with the cones) and flight.png (angle to each cone, Psi, e_R
    and e_Omega, Delta_bar, the motor commands, input ages, with failsafes and gaps ridden
    marked); panels whose topic the bag lacks say so. Returns the paths written.
    """
    paths = []
    if f.cones is not None and len(f.attitude_t):
        fig = Figure(figsize=(6, 6))
        ax = fig.add_subplot(projection='3d')
        sphere_path(ax, f.sensor_path, f.cones)
        ax.set_title('sensor axis on the unit sphere (%s)' % f.attitude_source)
        paths.append(os.path.join(out_dir, 'sensor_path.png'))
        fig.savefig(paths[-1], dpi=100)
    fig, axs = _subplots(4, 2, figsize=(12, 13))
    panels = [
        ('angle to each cone [deg] (dashed: half-angle)', None),
        ('Psi', f.psi), ('e_R', f.e_R), ('e_Omega [rad/s]', f.e_Omega),
        ('Delta_bar', f.delta_bar), ('motor commands (normalised)', f.motors),
        ('input age at the controller [ms]', None), ('state', None)]
    for ax, (title, series) in zip(axs.flat, panels):
        ax.set_title(title, fontsize=10)
        ax.grid(True, alpha=0.3)
        if series is not None:
            t, v = series
            if len(t):
                if title == 'Psi':
                    ax.semilogy(t, np.maximum(v, 1e-12))
                elif v.ndim == 2:
                    names = 'xyz' if v.shape[1] == 3 else [str(i + 1) for i in range(v.shape[1])]
                    for i, name in enumerate(names):
                        ax.plot(t, v[:, i], lw=0.8, label=name)
                    ax.legend(fontsize=7, ncol=len(names))
                else:
                    ax.plot(t, v, lw=0.8)
            else:
                ax.text(0.5, 0.5, 'not in the bag', ha='center', transform=ax.transAxes)
    ax = axs[0, 0]
    if f.cones is not None and len(f.attitude_t):
        for i, name in enumerate(f.cones.names):
            line, = ax.plot(f.attitude_t, f.cone_angles[:, i], label=name)
            ax.axhline(math.degrees(f.cones.theta[i]), color=line.get_color(), ls='--', lw=1)
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, 'no attitude or no cones', ha='center', transform=ax.transAxes)
    ax = axs[3, 0]
    if len(f.diag_t):
        ax.plot(f.diag_t, f.pose_age_ms, label='pose')
        ax.plot(f.diag_t, f.imu_age_ms, label='imu')
        ax.legend(fontsize=8)
    ax = axs[3, 1]
    if len(f.diag_t):
        ax.step(f.diag_t, f.armed, where='post', label='armed')
        for t in f.failsafe_t:
            ax.axvline(t, color='tab:red', lw=1)
        ax.set_yticks([0, 1], ['disarmed', 'armed'])
        ax.set_title('armed (red: failsafes)', fontsize=10)
    for ax in axs[-1]:
        ax.set_xlabel('t since the first message [s]')
    fig.tight_layout()
    paths.append(os.path.join(out_dir, 'flight.png'))
    fig.savefig(paths[-1], dpi=90)
    return paths


def compare_figure(f, headless, t_arm, out_dir):
    """compare.png: a recorded flight (``report``) and its headless twin (``report --compare``),
    the angle to each cone and Psi against the time since arming.
    """
    fig, (a1, a2) = _subplots(1, 2, figsize=(12, 4.5))
    t_h = headless.history[:, 0]
    for i, name in enumerate(f.cones.names if f.cones is not None else []):
        line, = a1.plot(f.attitude_t - t_arm, f.cone_angles[:, i], label='%s, recorded' % name)
        a1.plot(t_h, headless.history[:, headless.columns.index('angle_' + name)], ls='--',
                color=line.get_color(), label='%s, headless' % name)
        a1.axhline(math.degrees(f.cones.theta[i]), color=line.get_color(), lw=0.8, ls=':')
    a1.set(xlabel='t since arming [s]', ylabel='deg', title='angle to each cone')
    t, psi = f.psi
    a2.semilogy(t - t_arm, np.maximum(psi, 1e-12), label='recorded')
    a2.semilogy(t_h, np.maximum(headless.history[:, headless.columns.index('psi')], 1e-12),
                ls='--', label='headless')
    a2.set(xlabel='t since arming [s]', title='Psi', xlim=(0, t_h[-1] if len(t_h) else 1))
    a1.set_xlim(0, t_h[-1] if len(t_h) else 1)
    for a in (a1, a2):
        a.legend(fontsize=8)
        a.grid(True, alpha=0.3)
    fig.tight_layout()
    path = os.path.join(out_dir, 'compare.png')
    fig.savefig(path, dpi=100)
    return path
