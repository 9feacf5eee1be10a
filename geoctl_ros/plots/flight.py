"""A flight's figures: the sim-in-the-loop demo's, a recorded flight's, and a flight against
its headless replay.
"""
import math
import os

from matplotlib.figure import Figure
import numpy as np

from geoctl_ros.plots.common import sphere_path, subplots


def sil_figure(out, t, angles, cones, err, psi, cmd_t, commands):
    """sil.png: a sim-in-the-loop flight as recorded over DDS (``geoctl_ros.cli.demo``)."""
    fig, axs = subplots(2, 2, figsize=(11, 7))
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
    """The figures of a recorded flight (``geoctl_ros.records.report``): sensor_path.png (the
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
    fig, axs = subplots(4, 2, figsize=(12, 13))
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
    fig, (a1, a2) = subplots(1, 2, figsize=(12, 4.5))
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

