"""A campaign's figures: the closest approaches, the worst runs, a gain study's front."""

from matplotlib.ticker import FormatStrFormatter
import numpy as np

from geoctl_ros.plots.common import sky, subplots


def closest_approach_figure(closest_deg, path):
    """A campaign's histogram of the closest approach per run."""
    fig, ax = subplots(figsize=(7, 3.5))
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
    dt, its ConeSet)]): cone margin in time, and the worst one's sensor path.
    """
    fig, (a1, a2) = subplots(1, 2, figsize=(11, 4))
    for name, margins, _, dt, _ in flown:
        a1.plot(np.arange(len(margins)) * dt, margins, lw=1, label=name)
    a1.axhline(0.0, color='k', lw=0.8)
    a1.set(xlabel='t [s]', ylabel='cone margin [deg]', title='the %d worst runs' % len(flown))
    a1.legend(fontsize=7)
    a1.grid(True, alpha=0.3)
    name, _, sensor, _, cones = flown[0]
    sky(a2, sensor.astype(float), cones, '%s: sensor path' % name)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def gain_study_figure(figures, labels, front, path):
    """A gain study: each gain set's closest approach (p1) against its median settle time, the
    non-dominated sets marked (``geoctl_ros.campaign.study``).
    """
    fig, ax = subplots(figsize=(8, 5))
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



def tuning_figure(done, front, path):
    """A tuning: each trial's median settle time against its 95th percentile, the feasible ones
    filled and the Pareto front joined (``geoctl_ros.campaign.tune``); and the best feasible p95
    so far against the trials.
    """
    fig, (a1, a2) = subplots(1, 2, figsize=(11, 4.2))
    ok = [d for d in done if d[2].feasible]
    bad = [d for d in done if not d[2].feasible]
    if bad:
        a1.scatter([d[2].settle_p50_s for d in bad], [d[2].settle_p95_s for d in bad],
                   facecolors='none', edgecolors='tab:red', label='infeasible (%d)' % len(bad))
    if ok:
        a1.scatter([d[2].settle_p50_s for d in ok], [d[2].settle_p95_s for d in ok],
                   color='tab:blue', label='feasible (%d)' % len(ok))
    if front:
        xs = [d[2].settle_p50_s for d in front]
        ys = [d[2].settle_p95_s for d in front]
        order = np.argsort(xs)
        a1.plot(np.array(xs)[order], np.array(ys)[order], 'k-', lw=1, label='Pareto front')
        for d in front:
            a1.annotate('trial %d' % d[0], (d[2].settle_p50_s, d[2].settle_p95_s), fontsize=7,
                        xytext=(4, 4), textcoords='offset points')
    a1.set(xscale='log', yscale='log', xlabel='settle time, median [s]',
           ylabel='settle time, 95th percentile [s]',
           title='%d trials (unsettled runs count as twice the run)' % len(done))
    for axis in (a1.xaxis, a1.yaxis):        # plain numbers on the log scales
        axis.set_major_formatter(FormatStrFormatter('%g'))
        axis.set_minor_formatter(FormatStrFormatter('%g'))
    a1.legend(fontsize=8)
    a1.grid(True, which='both', alpha=0.3)
    best, so_far = np.inf, []
    for d in done:
        if d[2].feasible:
            best = min(best, d[2].settle_p95_s)
        so_far.append(best)
    a2.step(np.arange(len(done)), so_far, where='post', color='tab:blue')
    a2.set(xlabel='trial', ylabel='best feasible p95 so far [s]', title='the search')
    a2.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def falsification_figure(searches, outside, path):
    """A falsification: each search's lowest robustness found against the evaluations spent, one
    panel per requirement searched (``geoctl_ros.falsify.search.Search``; outside: the
    robustness of a point outside the envelope).
    """
    targets = sorted({s.target for s in searches})
    fig, axes = subplots(1, len(targets), figsize=(5.5 * len(targets), 3.8), squeeze=False)
    for ax, target in zip(axes[0], targets):
        for s in searches:
            if s.target == target:
                low = s.running_min()
                low = np.where(low >= outside, np.nan, low)      # none inside yet
                ax.step(np.arange(1, len(low) + 1), low, where='post', label=s.optimizer)
        ax.axhline(0.0, color='tab:red', lw=1, label='violated below')
        ax.set(xlabel='evaluations', ylabel='lowest robustness found [deg]',
               title='requirement %r' % target)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
