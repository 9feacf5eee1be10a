"""What the figures share: a Figure of its own (no pyplot state, so no display and no backend
are needed), and the sensor's path with the cones on the sphere and on a sky map.
"""
import math

from matplotlib.figure import Figure
import numpy as np

from geoctl_ros.core.geometry import sphere


def subplots(*grid, figsize, **kw):
    """(figure, axes) like pyplot.subplots, on a Figure of its own."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*grid, **kw)


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


def az_el(d):
    """Azimuth and elevation (deg) of world directions (..., 3)."""
    d = np.atleast_2d(d)
    return (np.degrees(np.arctan2(d[:, 1], d[:, 0])),
            np.degrees(np.arcsin(np.clip(d[:, 2], -1, 1))))


def sky_cones(ax, cones, title):
    """A sky map (azimuth / elevation) with the boundaries of the cones (a ConeSet)."""
    for v, th in zip(cones.V, cones.theta):
        ring = np.array([sphere.direction(v, th, a)
                         for a in np.linspace(0, 2 * math.pi, 181)])
        az, el = az_el(ring)
        ax.plot(az, el, '.', ms=1.5, color='tab:red')
    ax.set(xlabel='azimuth [deg]', ylabel='elevation [deg]', title=title, xlim=(-180, 180),
           ylim=(-90, 90))
    ax.grid(True, alpha=0.3)


def sky_path(ax, path, color, label=None, end_color=None):
    """The sensor's world direction (path: (N, 3)) on a sky map, its end marked."""
    az, el = az_el(path)
    ax.plot(az, el, '.', ms=1.5, color=color)
    ax.plot(az[-1], el[-1], 's', color=end_color or color, ms=5, label=label)


def sky(ax, path, cones, title):
    """The sensor's world direction in azimuth / elevation, with the cones' (a ConeSet)
    boundaries.
    """
    sky_cones(ax, cones, title)
    az, el = az_el(path)
    ax.plot(az[0], el[0], 'o', color='tab:green', label='start')
    sky_path(ax, path, 'tab:blue', label='end', end_color='k')
    ax.legend(fontsize=7)
