"""The benchmark's figures: per case, every law's sensor path with the cones, and its margins."""
import numpy as np

from geoctl_ros.plots.common import az_el, sky_cones, sky_path, subplots

COLORS = ('tab:blue', 'tab:orange', 'tab:purple', 'tab:green', 'tab:brown', 'tab:pink')
STYLES = ('-', '--', '-', '-', '-', '-')     # (the delay-robust law is the paper's when not blind)


def case_figure(title, cones, flights, path):
    """One case flown by every law (flights: [(law, margin at each control step, sensor
    direction at each, dt)]): the sensor paths on a sky map with the cones, and the margins in
    time; a law that diverged has no series and is named in the legend.
    """
    fig, (a1, a2) = subplots(1, 2, figsize=(12, 4.5))
    sky_cones(a1, cones, '%s: sensor paths' % title)
    for (law, margins, sensor, dt), color, style in zip(flights, COLORS, STYLES):
        if not len(margins):
            a2.plot([], [], color=color, label='%s (diverged)' % law)
            continue
        sky_path(a1, sensor, color, label=law)
        az, el = az_el(sensor[:1])
        a1.plot(az, el, 'o', color='k', ms=4)
        a2.plot(np.arange(len(margins)) * dt, margins, lw=1.2, ls=style, color=color, label=law)
    a1.legend(fontsize=7)
    a2.axhline(0.0, color='k', lw=0.8)
    a2.set(xlabel='t [s]', ylabel='closest cone margin [deg] (negative: inside)',
           title='margin to the nearest cone')
    a2.legend(fontsize=7)
    a2.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def closest_figure(closest_by_law, path):
    """The random runs' closest approach per law (closest_by_law: {law: array}), as overlaid
    cumulative distributions.
    """
    fig, ax = subplots(figsize=(7, 4))
    for (law, closest), color, style in zip(closest_by_law.items(), COLORS, STYLES):
        x = np.sort(np.asarray(closest, dtype=float))
        ax.step(x, np.arange(1, len(x) + 1) / max(len(x), 1), where='post', color=color,
                ls=style, label='%s (%d runs)' % (law, len(x)))
    ax.axvline(0.0, color='tab:red', lw=1.2, label='cone boundary')
    ax.set(xlabel='closest approach to a cone [deg] (negative: inside)',
           ylabel='share of runs at or below', title='random manoeuvres: closest approach')
    ax.legend(fontsize=7)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
