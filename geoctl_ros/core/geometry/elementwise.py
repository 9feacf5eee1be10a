"""One formula for one run and for a batch, where the formula is elementwise (per run and cone,
or per component of a vector).

A formula written here takes ``ops`` (how to take a maximum, a minimum, a choice, a square
root, numpy's arccos, sine, cosine and logarithm) and its values, and uses only arithmetic,
comparisons and ``&``/``|`` besides: so it runs on Python floats (``FLOATS``) and on numpy
arrays (``ARRAYS``) alike, and gives the same bits on both (IEEE arithmetic and square roots
round alike on either, the choices are exact, and the transcendental functions are numpy's on
both). ``evaluate`` runs
it: a few elements (one run's cones) one by one in Python floats, where a numpy call would cost
more than its arithmetic (about 1 us a call against 0.05 us a float operation), and more elements
(a batch) in whole-array operations. A run alone and in a batch of any size therefore gives the
same bits (test/test_elementwise.py). Vectors and matrices go by their components
(``vector_parts``, ``matrix_parts``, ``joined``): the formula then names each product's terms,
in the index order of ``so3``'s stacked products.
"""
import math
from typing import Callable, List, Sequence, Tuple, TypeVar, Union, cast

import numpy as np

from geoctl_ros.core.geometry.quaternions import BoolArray, FloatArray, Scalars

FLOATS_MAX = 16        # elements up to which a formula runs element by element in floats

Value = Scalars                      # one element's value, or one per element of a batch
Flag = Union[bool, BoolArray]        # one element's flag, or one per element of a batch
ResultT = TypeVar('ResultT')


def _choose(condition: Flag, a: Value, b: Value) -> Value:
    return a if condition else b


class Ops:
    """How a formula takes its non-arithmetic steps, on floats or on arrays."""

    def __init__(self, maximum: Callable[[Value, Value], Value],
                 minimum: Callable[[Value, Value], Value],
                 where: Callable[[Flag, Value, Value], Value], sqrt: Callable[[Value], Value],
                 every: Callable[[Flag], bool], some: Callable[[Flag], bool],
                 arccos: Callable[[Value], Value], sin: Callable[[Value], Value],
                 both: Callable[[Callable[[Value], Value], Value, Value],
                                Tuple[Value, Value]],
                 cos: Callable[[Value], Value], log: Callable[[Value], Value]) -> None:
        self.maximum = maximum      # maximum(a, b): elementwise (a where equal)
        self.minimum = minimum      # minimum(a, b): elementwise (a where equal)
        self.where = where          # where(condition, a, b): a where condition, else b
        self.sqrt = sqrt
        self.every = every          # every(flags): whether all are true (a short cut's test)
        self.some = some            # some(flags): whether any is true (a short cut's test)
        self.arccos = arccos        # numpy's, on floats too (the math module's need not round
        self.sin = sin              # as numpy's do)
        self.cos = cos
        self.log = log
        self.both = both            # both(f, a, b): (f(a), f(b)); a batch's in one evaluation


def _both_floats(f: Callable[[Value], Value], a: Value, b: Value) -> Tuple[Value, Value]:
    return f(a), f(b)


def _both_arrays(f: Callable[[Value], Value], a: Value, b: Value) -> Tuple[Value, Value]:
    out = cast(FloatArray, f(np.stack(np.broadcast_arrays(a, b))))      # (the same entries)
    return out[0], out[1]


def _float_of(function: Callable[[Value], Value]) -> Callable[[Value], Value]:
    """A numpy function of one float, as a float."""
    return lambda x: float(function(x))


FLOATS = Ops(cast(Callable[[Value, Value], Value], max),
             cast(Callable[[Value, Value], Value], min), _choose,
             cast(Callable[[Value], Value], math.sqrt), bool, bool, _float_of(np.arccos),
             _float_of(np.sin), _both_floats, _float_of(np.cos), _float_of(np.log))
ARRAYS = Ops(np.maximum, np.minimum, np.where, np.sqrt, lambda flags: bool(np.all(flags)),
             lambda flags: bool(np.any(flags)), np.arccos, np.sin, _both_arrays, np.cos, np.log)


def evaluate(formula: Callable[..., ResultT], *values: Union[Value, Flag]) -> ResultT:
    """formula(ops, *values) for every element of the values broadcast together (floats, or
    arrays of any shapes that broadcast): the result, or a tuple of results, as floats where
    every value is a float, else as arrays of the broadcast shape. (What is the same for every
    element, bounds and spans, the caller binds: ``lambda ops, *v: f(ops, bound, *v)``.)
    """
    if all(isinstance(v, float) for v in values):
        return formula(FLOATS, *(float(v) for v in values))
    arrays = [np.asarray(v, dtype=float) for v in values if not isinstance(v, float)]
    shape = arrays[0].shape
    if any(a.shape != shape for a in arrays):
        shape = np.broadcast_shapes(*(a.shape for a in arrays))
    size = math.prod(shape)
    if size > FLOATS_MAX or not size:
        return formula(ARRAYS, *(v if isinstance(v, float) else np.asarray(v, dtype=float)
                                 for v in values))
    columns = [[float(v)] * size if isinstance(v, float) else _elements(v, shape)
               for v in values]
    results = [formula(FLOATS, *element) for element in zip(*columns)]
    if not isinstance(results[0], tuple):              # (a float or a flag per element)
        return cast(ResultT, _array(cast('List[float]', results), shape))
    return cast(ResultT, tuple(_array(part, shape)
                               for part in zip(*cast('List[Tuple[float, ...]]', results))))


def _elements(v: Union[Value, Flag], shape: Tuple[int, ...]) -> List[float]:
    """An array's elements broadcast to shape, as floats."""
    a = np.asarray(v, dtype=float)
    return cast('List[float]', (a if a.shape == shape else np.broadcast_to(a, shape)).ravel()
                .tolist())


def _array(elements: Sequence[Union[float, bool]], shape: Tuple[int, ...]) -> FloatArray:
    """Elements (floats, or flags) as an array of shape."""
    out = np.array(elements, dtype=bool if isinstance(elements[0], bool) else float)
    return out if len(shape) == 1 else out.reshape(shape)


# Vectors and matrices by their components: a formula over the components of 3-vectors and 3x3
# matrices (nested lists: v[i], M[i][j]) runs on one run's floats and on a batch's arrays alike,
# with the operations of the stacked products (``so3.matvec``: sums of products in index order).

def one_run(M: FloatArray) -> bool:
    """Whether a stack of matrices (..., n, m) is one run's: one matrix, or a batch of one."""
    return M.ndim == 2 or M.shape[:-2] == (1,)


def vector_parts(v: FloatArray, one: bool) -> List[Value]:
    """A vector's components (..., n): floats for one run (``one``), else arrays (views)."""
    if one:
        return cast('List[Value]', (v if v.ndim == 1 else v[0]).tolist())
    return [v[..., k] for k in range(v.shape[-1])]


def matrix_parts(M: FloatArray, one: bool) -> List[List[Value]]:
    """A matrix's components (..., n, m) as rows: floats for one run, else arrays (views)."""
    if one:
        return cast('List[List[Value]]', (M if M.ndim == 2 else M[0]).tolist())
    return [[M[..., i, j] for j in range(M.shape[-1])] for i in range(M.shape[-2])]


def joined(parts: Sequence[Value], lead: Tuple[int, ...], one: bool) -> FloatArray:
    """A vector from its components: of shape lead + (n,) for one run (lead () or (1,)), else
    stacked on a last axis.
    """
    if one:
        return np.array(parts if not lead else [parts], dtype=float)
    return np.stack(np.broadcast_arrays(*parts), axis=-1)


def joined_matrix(rows: Sequence[Sequence[Value]], lead: Tuple[int, ...],
                  one: bool) -> FloatArray:
    """A matrix from its components by rows: of shape lead + (n, m) for one run, else stacked
    on the last two axes.
    """
    if one:
        return np.array(rows if not lead else [rows], dtype=float)
    return np.stack([np.stack(np.broadcast_arrays(*row), axis=-1) for row in rows], axis=-2)
