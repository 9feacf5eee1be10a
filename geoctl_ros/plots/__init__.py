"""Every figure, drawn with matplotlib: the development tools' extra ``tools`` (setup.py), which
the vehicle has not. The modules of this package import matplotlib; this one does not, so that
the commands that also run on the vehicle (scenario, report, the demo's flight) ask it first.
"""
import importlib.util
import sys

EXTRA = 'tools'


def available(command: str) -> bool:
    """Whether COMMAND can draw its figures here; if not (no matplotlib), one line on stderr says
    that they are skipped and how to get them.
    """
    if importlib.util.find_spec('matplotlib') is not None:
        return True
    print("%s: no figures: matplotlib is not installed here (the extra '%s': pip install -e "
          "'.[%s]' in a clone, or draw them on a development machine); the rest is written"
          % (command, EXTRA, EXTRA), file=sys.stderr)
    return False
