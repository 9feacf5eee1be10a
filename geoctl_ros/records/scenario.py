"""A scenario run's files: DIR/summary.json, DIR/history.csv (one row per control step) and the
PNG figures like the paper's (``geoctl_ros.plots``, imported only to draw them: matplotlib is the
development tools' extra, and ``scenario`` runs on the vehicle without it).
"""
import json
import os

import numpy as np


def write(result, out_dir, plots=True):
    """Write summary.json, history.csv and (if plots) the PNG figures into out_dir."""
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, 'summary.json'), 'w') as f:
        json.dump(result.summary, f, indent=2)
        f.write('\n')
    np.savetxt(os.path.join(out_dir, 'history.csv'), result.history, delimiter=',',
               header=','.join(result.columns), comments='', fmt='%.9g')
    if plots:
        from geoctl_ros.plots import scenario as scenario_plots  # noqa: PLC0415  (matplotlib)
        scenario_plots.scenario_figures(result, out_dir)

