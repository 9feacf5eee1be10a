"""What the command-line front ends share: argparse types, the cluster's arguments and refusals."""
import argparse
import functools
import math
import os
import sys
from typing import Any, Callable

from geoctl_ros import RoundingError


def positive_seconds(text: str) -> float:
    """An argparse type: a positive, finite number of seconds (nan, inf, 0 and words refused)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError('%r is not a positive number of seconds' % text)
    return value


def on_a_cluster(prog: str) -> Callable[[Callable[..., int]], Callable[..., int]]:
    """A command's main that flies on a cluster: a worker refused for its numpy's rounding
    (``geoctl_ros.RoundingError``, from ``campaign.cluster``) is said in one line, exit code 2.
    """
    def wrap(main: Callable[..., int]) -> Callable[..., int]:
        @functools.wraps(main)
        def refusing(*args: Any, **kwargs: Any) -> int:
            try:
                return main(*args, **kwargs)
            except RoundingError as e:
                print('%s: refused: %s' % (prog, e), file=sys.stderr)
                return 2
        return refusing
    return wrap


def cannot_start(prog: str, error: Exception, path: str) -> int:
    """Say in one line why a command cannot start: a bad parameter file (ConfigError, its own
    message) or a file it cannot read or write (OSError, on path unless the error names one);
    the exit code, 2.
    """
    if isinstance(error, OSError):
        print('%s: %s: %s' % (prog, error.filename or path, error.strerror or error),
              file=sys.stderr)
    else:
        print('%s: %s' % (prog, error), file=sys.stderr)
    return 2


def add_cluster_arguments(parser: argparse.ArgumentParser, *worker_aliases: str) -> None:
    """--workers (and its aliases) and --scheduler: where a command's batches fly."""
    parser.add_argument('--workers', *worker_aliases, type=int, default=os.cpu_count() or 1,
                        dest='workers', help='local cluster: worker processes (one per core)')
    parser.add_argument('--scheduler', metavar='tcp://HOST:PORT', default=None,
                        help='fly on this Dask scheduler instead of a local cluster')
