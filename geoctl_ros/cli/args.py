"""What the command-line front ends share: argparse types."""
import argparse
import math
import os
import sys


def positive_seconds(text: str) -> float:
    """An argparse type: a positive, finite number of seconds (nan, inf, 0 and words refused)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError('%r is not a positive number of seconds' % text)
    return value


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
