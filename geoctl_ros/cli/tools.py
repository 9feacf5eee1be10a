"""The development tools' front door: ``python -m geoctl_ros.cli.tools COMMAND [ARGS]`` (what
``./run COMMAND`` runs) and the console scripts ``soak``, ``campaign``, ``tune``, ``falsify`` and
``benchmark``.

The tools run on a development machine or a lab workstation, not on the vehicle. Most need, beyond
the flight package, modules of setup.py's extra ``tools`` (matplotlib, Dask, Optuna, Psi-TaLiRo,
RTAMT, scipy, Hypothesis), which ``./run`` installs into the development stack. Where a tool's
modules are not installed (the vehicle's stack, a ``colcon build`` from rosdep's keys), its
command says so in one line, and how to get them, before it imports anything of its own, and
exits 2. Those that need none of them (soak, sensors, and the demo, which then draws no figure)
run anywhere the flight package does. This module imports nothing but the standard library (and
the plots package's constant, not matplotlib).
"""
import importlib
import importlib.util
import sys
from typing import List, Optional, Sequence

from geoctl_ros.plots import EXTRA

WHERE = ("A development tool: it runs on a development machine or a lab workstation (./run, or "
         "pip install -e '.[%s]' in a clone), not on the vehicle." % EXTRA)

# command: (what it does, the modules it imports beyond the flight package's dependencies)
TOOLS = {
    'campaign': ('safety campaigns on a Dask cluster', ('dask', 'distributed', 'matplotlib')),
    'tune': ('gain tuning', ('optuna', 'dask', 'distributed', 'matplotlib')),
    'falsify': ('falsification',
                ('staliro', 'rtamt', 'scipy', 'dask', 'distributed', 'matplotlib')),
    'benchmark': ("the laws' benchmark", ('dask', 'distributed', 'matplotlib')),
    'soak': ('load and fault runs of the sim in the loop', ()),
    'demo': ('the sim-in-the-loop demo', ()),
    'sensors': ("the sensor conventions' sim-in-the-loop runs", ()),
    'fuzz': ('the hostile-input fuzzer', ('hypothesis',)),
}
# the package index's names of the modules that are not their own
DISTRIBUTIONS = {'staliro': 'psy-taliro'}


def missing(command: str) -> List[str]:
    """The modules COMMAND needs that are not installed here (their index names)."""
    return [DISTRIBUTIONS.get(m, m) for m in TOOLS[command][1]
            if importlib.util.find_spec(m) is None]


def refusal(command: str, absent: Sequence[str]) -> str:
    """The one line that says COMMAND cannot run here, and why, and where it does."""
    return ("%s: a development tool (%s), not part of the flight package: it needs %s (the "
            "extra '%s'), not installed here. Run it on a development machine: ./run %s, or "
            "pip install -e '.[%s]' in a clone first."
            % (command, TOOLS[command][0], ', '.join(absent), EXTRA, command, EXTRA))


def run(command: str, argv: Optional[Sequence[str]] = None) -> int:
    """COMMAND's main with argv (default: this process's), or the refusal and 2."""
    absent = missing(command)
    if absent:
        print(refusal(command, absent), file=sys.stderr)
        return 2
    module = importlib.import_module('geoctl_ros.cli.' + command)
    return module.main(None if argv is None else list(argv))


def soak() -> None:
    sys.exit(run('soak'))


def campaign() -> None:
    sys.exit(run('campaign'))


def tune() -> None:
    sys.exit(run('tune'))


def falsify() -> None:
    sys.exit(run('falsify'))


def benchmark() -> None:
    sys.exit(run('benchmark'))


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``python -m geoctl_ros.cli.tools COMMAND [ARGS]``."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] not in TOOLS:
        print('usage: python -m geoctl_ros.cli.tools {%s} [args]' % ','.join(TOOLS),
              file=sys.stderr)
        return 2
    return run(args[0], args[1:])


if __name__ == '__main__':
    sys.exit(main())
