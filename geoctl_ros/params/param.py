"""A parameter's declaration (``Param``), the node kinds, ``ConfigError`` and the checks the
schema's entries use (``geoctl_ros.params.schema`` lists them).
"""
from dataclasses import dataclass
from typing import Any, Callable, Optional, Sequence

import numpy as np

from geoctl_ros.core.geometry.quaternions import quaternion_problem
from geoctl_ros.params.topics import TOPICS as _RECORDED

CONTROLLER, SIM, SCENARIO, MAVLINK, RECORD, VIEW, ESC = (
    'controller', 'sim', 'scenario', 'mavlink_bridge', 'record', 'view', 'esc_i2c')
BOTH = (CONTROLLER, SIM)
MOTOR_TEST_COMMAND_MAX = 0.3       # the largest motor-test command (normalised)
MOTOR_TEST_DURATION_MAX = 10.0     # s, the longest motor test
RECORD_TOPICS = tuple(t.name for t in _RECORDED)

# The lab's inertia about the centre of mass is given in its code's forward-right-down body frame;
# in this package's forward-left-up frame (F = diag(1, -1, -1), J_FLU = F J_FRD F) the products
# J12 and J13 change sign and J23 does not.
LAB_INERTIA = [5.5710e-3, -6.1766e-5, 2.5028e-5,
               -6.1766e-5, 5.5757e-3, 1.0068e-5,
               2.5028e-5, 1.0068e-5, 1.0505e-2]


class ConfigError(ValueError):
    """One or more invalid parameters; ``errors`` lists (parameter, reason) pairs."""

    def __init__(self, errors):
        self.errors = list(errors)
        super().__init__('invalid parameters:\n' + '\n'.join(
            '  %s: %s' % (name, reason) for name, reason in self.errors))

    def __reduce__(self):
        # (rebuilt from its pairs in another process, a Dask worker's or a pool's; the default
        # would pass the message as the pairs)
        return (ConfigError, (self.errors,))


# --- checks: each returns a reason (str) or None ------------------------------------------------
def positive(v: float) -> Optional[str]:
    return None if v > 0.0 else 'must be > 0 (got %r)' % v


def nonzero_vector(v: np.ndarray) -> Optional[str]:
    # (the largest element, not the norm: a norm of 1e200 overflows)
    return None if np.abs(v).max() > 1e-9 else 'must not be the zero vector'


def unit_quaternion(q: np.ndarray) -> Optional[str]:
    problem = quaternion_problem(q)
    return None if problem is None else 'must be a unit quaternion (x, y, z, w): ' + problem


def half_angle(v: float) -> Optional[str]:
    return None if 0.0 < v < 90.0 else 'must be in (0, 90) degrees (got %r)' % v


def diagonal_weights(G: np.ndarray) -> Optional[str]:
    if min(G) <= 0.0:
        return 'weights must be positive (got %s)' % list(G)
    if len(set(G)) < 3:
        return 'weights must be distinct (Prop. 1 of the paper; got %s)' % list(G)
    return None


def inertia_matrix(vals: np.ndarray) -> Optional[str]:
    J = np.asarray(vals).reshape(3, 3)
    if not np.allclose(J, J.T, rtol=0.0, atol=1e-12 + 1e-9 * np.abs(J).max()):
        return 'must be symmetric (row-major 3x3)'
    eig = np.linalg.eigvalsh(J)
    if eig[0] <= 0.0:
        return 'must be positive definite (smallest eigenvalue %.3g)' % eig[0]
    if eig[0] + eig[1] < eig[2] * (1.0 - 1e-9):
        return 'violates the triangle inequality of principal moments (not a physical body)'
    return None


def i2c_addresses(v: np.ndarray) -> Optional[str]:
    if not len(v) or any(not 0x03 <= a <= 0x77 for a in v):
        return 'must be 7-bit addresses 0x03 to 0x77'
    return None if len(set(v)) == len(v) else 'must be different'


@dataclass(frozen=True)
class Param:
    """One parameter: ROS type ('double', 'double_array', 'bool', 'string', 'string_array'),
    array length (0: any), default, unit, one-line doc, the nodes that read it, and a check.
    """

    name: str
    type: str
    default: Any
    unit: str
    doc: str
    nodes: tuple
    length: int = 0
    check: Optional[Callable[[Any], Optional[str]]] = None
    choices: tuple = ()
    lo: Optional[float] = None      # the least value (of each element, for arrays); None: none
    hi: Optional[float] = None      # the greatest

    @property
    def range_text(self) -> str:
        """The documented range, as docs/parameters.md shows it ('' for non-numbers)."""
        if self.lo is None or self.hi is None:
            return ''
        return '[%s, %s]' % (number_text(self.lo), number_text(self.hi))


def number_text(x: float) -> str:
    return '%d' % x if isinstance(x, int) else '%g' % x


def declare(name: str, type_: str, default: Any, unit: str, doc: str, nodes: Any, length: int = 0,
            check: Optional[Callable[[Any], Optional[str]]] = None, choices: Sequence = (),
            lo: Optional[float] = None, hi: Optional[float] = None) -> 'Param':
    return Param(name, type_, default, unit, doc, nodes if isinstance(nodes, tuple) else (nodes,),
                 length, check, tuple(choices), lo, hi)

