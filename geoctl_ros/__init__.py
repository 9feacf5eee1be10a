"""geoctl_ros: geometric adaptive constrained attitude control on SO(3) for a hexrotor testbed.

Importing the package first (every console script, node and runner does) keeps numpy off its
AVX-512 kernels of exp, log, arccos, arcsin, arctan, arctan2, power and the like, in this process
and in the processes it starts: those kernels round otherwise than the C library's functions that
numpy uses on every other CPU (and otherwise in numpy 1.26 than in numpy 2), so a flight would
give other bits on a CPU with AVX-512 than on one without, and on the vehicle's stack than on the
development stack (docs/speed.md, "The same bits"). Numpy's other kernels stay as they are (their
results do not depend on the CPU). A NPY_DISABLE_CPU_FEATURES set beforehand is left as it is: an
empty one leaves numpy as it comes (a numpy built with AVX-512 in its baseline refuses to import
with them disabled). ``numpy_rounding_problem`` says whether a process rounds otherwise: the
clusters' workers are checked with it, and ``scenario`` warns.
"""
import functools as _functools
import os as _os
import sys as _sys

# numpy's names of its AVX-512 targets: since numpy 2.4 grouped (x86-64-v4), before apart
_AVX512_TARGETS = {(2, 4): 'X86_V4 AVX512_ICL AVX512_SPR',
                   (2, 0): 'AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX '
                           'AVX512_CNL AVX512_ICL AVX512_SPR',
                   (0, 0): 'AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX '
                           'AVX512_CNL AVX512_ICL'}


def avx512_targets():
    """numpy's names of its AVX-512 targets for the numpy installed here, on x86-64 (what
    NPY_DISABLE_CPU_FEATURES takes), else None (another CPU: numpy has no such kernels).
    Found without importing numpy.
    """
    import platform  # noqa: PLC0415  (only here: at the package's import)
    if platform.machine().lower() not in ('x86_64', 'amd64'):
        return None
    from importlib import metadata  # noqa: PLC0415
    try:
        version = tuple(int(part) for part in metadata.version('numpy').split('.')[:2])
    except (metadata.PackageNotFoundError, ValueError):
        return None
    return next(names for since, names in _AVX512_TARGETS.items() if version >= since)


def _numpy_as_on_every_cpu():
    """Set NPY_DISABLE_CPU_FEATURES to numpy's AVX-512 targets before numpy is imported."""
    if 'numpy' in _sys.modules or 'NPY_DISABLE_CPU_FEATURES' in _os.environ:
        return
    targets = avx512_targets()
    if targets:
        _os.environ['NPY_DISABLE_CPU_FEATURES'] = targets


_numpy_as_on_every_cpu()


class RoundingError(RuntimeError):
    """A process (a cluster's worker) whose numpy does not round as the package's processes do
    (``numpy_rounding_problem``): what it flew would not be what it flies elsewhere.
    """


@_functools.lru_cache(maxsize=1)          # (a process's numpy does not change)
def numpy_rounding_problem():
    """Why numpy in this process does not round as the package's processes do (a sentence), or
    None: exp, arccos and arctan2 on arrays must give the C library's bits, as they do with the
    setting above and on every CPU without AVX-512. A process that imported numpy before this
    package (a ``dask worker`` started plainly) runs numpy's AVX-512 kernels where the CPU has
    them: its flights' bits are another CPU's.
    """
    import math  # noqa: PLC0415

    import numpy as np  # noqa: PLC0415
    x = np.linspace(-0.999, 0.999, 257)
    y = 5.0 * x[::-1]
    if (np.array_equal(np.exp(y), [math.exp(v) for v in y])
            and np.array_equal(np.arccos(x), [math.acos(v) for v in x])
            and np.array_equal(np.arctan2(x, y), [math.atan2(a, b) for a, b in zip(x, y)])):
        return None
    return ("numpy in this process rounds exp, arccos or arctan2 otherwise than the C library "
            "(its AVX-512 kernels: numpy was imported before geoctl_ros, or "
            "NPY_DISABLE_CPU_FEATURES was set otherwise), so its flights would "
            "not give the bits they give elsewhere: start it with NPY_DISABLE_CPU_FEATURES='%s' "
            "in its environment (docs/campaigns.md)" % (avx512_targets() or ''))
