"""geoctl_ros: geometric adaptive constrained attitude control on SO(3) for a hexrotor testbed.

Importing the package first (every console script, node and runner does) keeps numpy off its
AVX-512 kernels of exp, log, arccos, arcsin, arctan, arctan2, power and the like, in this process
and in the processes it starts: those kernels round otherwise than the C library's functions that
numpy uses on every other CPU (and otherwise in numpy 1.26 than in numpy 2), so a flight would
give other bits on a CPU with AVX-512 than on one without, and on the vehicle's stack than on the
development stack (docs/speed.md, "The same bits"). Numpy's other kernels stay as they are (their
results do not depend on the CPU). A NPY_DISABLE_CPU_FEATURES set beforehand is left as it is.
"""
import os as _os
import sys as _sys

# numpy's names of its AVX-512 targets: since numpy 2.4 grouped (x86-64-v4), before apart
_AVX512_TARGETS = {(2, 4): 'X86_V4 AVX512_ICL AVX512_SPR',
                   (2, 0): 'AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX '
                           'AVX512_CNL AVX512_ICL AVX512_SPR',
                   (0, 0): 'AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX '
                           'AVX512_CNL AVX512_ICL'}


def _numpy_as_on_every_cpu():
    """Set NPY_DISABLE_CPU_FEATURES to numpy's AVX-512 targets, before numpy is imported, on
    x86-64 (elsewhere numpy has no such kernels to leave out).
    """
    if 'numpy' in _sys.modules or 'NPY_DISABLE_CPU_FEATURES' in _os.environ:
        return
    import platform  # noqa: PLC0415  (only here: at the package's import)
    if platform.machine().lower() not in ('x86_64', 'amd64'):
        return
    from importlib import metadata  # noqa: PLC0415
    try:
        version = tuple(int(part) for part in metadata.version('numpy').split('.')[:2])
    except (metadata.PackageNotFoundError, ValueError):
        return
    _os.environ['NPY_DISABLE_CPU_FEATURES'] = next(
        names for since, names in _AVX512_TARGETS.items() if version >= since)


_numpy_as_on_every_cpu()
