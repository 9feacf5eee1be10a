"""A scenario run's figures, after the paper's Figs. 2, 3 and 5, each written to a PNG."""
import os

from matplotlib.figure import Figure
import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.params import cone_set
from geoctl_ros.plots.common import sphere_path, subplots


def _col(result, name):
    return result.history[:, result.columns.index(name)]


def _cols(result, prefix):
    return [c for c in result.columns if c.startswith(prefix)]


def scenario_figures(result, out_dir):
    """Write attitude_error.png, psi.png, cone_angles.png, disturbance.png, control_moment.png,
    motor_commands.png (rotor actuation only) and sensor_path.png; returns their paths.
    """
    title = result.scenario.options.title or result.scenario.name
    t = _col(result, 't')
    paths = []

    def save(fig, name):
        fig.suptitle(title, fontsize=10)
        fig.tight_layout()
        path = os.path.join(out_dir, name)
        fig.savefig(path, dpi=110)
        paths.append(path)

    fig, ax = subplots(figsize=(7, 3.5))
    for i, c in enumerate(('eR_x', 'eR_y', 'eR_z')):
        ax.plot(t, _col(result, c), label='$e_{R,%d}$' % (i + 1))
    ax.set(xlabel='t [s]', ylabel='$e_R$', title='attitude error vector')
    ax.grid(True, alpha=0.3)
    ax.legend()
    save(fig, 'attitude_error.png')

    fig, ax = subplots(figsize=(7, 3.5))
    ax.plot(t, _col(result, 'psi'))
    ax.set(xlabel='t [s]', ylabel=r'$\Psi$', title=r'configuration error $\Psi$')
    ax.grid(True, alpha=0.3)
    save(fig, 'psi.png')

    fig, ax = subplots(figsize=(7, 3.5))
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

    fig, ax = subplots(figsize=(7, 3.5))
    for i, c in enumerate(_cols(result, 'dbar_')):
        line, = ax.plot(t, _col(result, c), label=r'$\bar\Delta_{%d}$' % (i + 1))
        ax.plot(t, _col(result, 'dtrue_%d' % i), color=line.get_color(), ls='--', lw=1)
    ax.set(xlabel='t [s]', ylabel='estimate', title=r'disturbance estimate $\bar\Delta$ '
           '(dashed: true unmodelled disturbance)')
    ax.grid(True, alpha=0.3)
    ax.legend(ncol=2)
    save(fig, 'disturbance.png')

    fig, ax = subplots(figsize=(7, 3.5))
    for c in ('u_x', 'u_y', 'u_z'):
        ax.plot(t, _col(result, c), label=c)
    ax.set(xlabel='t [s]', ylabel='moment [N m]', title='control moment u about the pivot')
    ax.grid(True, alpha=0.3)
    ax.legend()
    save(fig, 'control_moment.png')

    cmd_cols = _cols(result, 'cmd_')
    if cmd_cols:
        fig, (ax1, ax2) = subplots(2, 1, figsize=(7, 5.5), sharex=True)
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

