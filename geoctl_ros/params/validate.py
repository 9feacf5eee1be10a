"""Checking values against the schema, ROS-strict, and resolving a node's parameters."""
import difflib
import math
from typing import Any, Iterable, Optional, Sequence, Tuple

import numpy as np

from geoctl_ros.params.param import CONTROLLER, ConfigError, Param
from geoctl_ros.params.schema import BY_NAME, CONE_KEY, CONE_NAME, SCHEMA, cone_param, schema_for


def check_value(p: Param, value: Any) -> Tuple[Any, Optional[str]]:
    """(converted value, None) or (None, reason) for a value of parameter p, ROS-strict."""
    t = p.type
    out: Any
    if t == 'double':
        if isinstance(value, bool) or not isinstance(value, float):
            hint = ' (write %r)' % float(value) if isinstance(value, int) and not isinstance(
                value, bool) else ''
            return None, 'expected a double, got %s%s' % (_describe(value), hint)
        if not math.isfinite(value):
            return None, 'must be finite (got %r)' % value
        out = value
    elif t == 'double_array':
        if not isinstance(value, (list, tuple, np.ndarray)) or not all(
                isinstance(v, float) for v in value):
            hint = ''
            if isinstance(value, (list, tuple)) and all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
                hint = ' (write every element as a float, e.g. %s)' % [float(v) for v in value]
            return None, 'expected an array of doubles, got %s%s' % (_describe(value), hint)
        out = np.array(value, dtype=float)
        if p.length and out.size != p.length:
            return None, 'expected %d values, got %d' % (p.length, out.size)
        if not np.all(np.isfinite(out)):
            return None, 'must be finite'
    elif t == 'integer':
        if isinstance(value, bool) or not isinstance(value, int):
            return None, 'expected an integer, got %s' % _describe(value)
        out = value
    elif t == 'integer_array':
        if not isinstance(value, (list, tuple)) or not all(
                isinstance(v, int) and not isinstance(v, bool) for v in value):
            return None, 'expected an array of integers, got %s' % _describe(value)
        out = list(value)
        if p.length and len(out) != p.length:
            return None, 'expected %d values, got %d' % (p.length, len(out))
    elif t == 'bool':
        if not isinstance(value, bool):
            return None, 'expected true or false, got %s' % _describe(value)
        out = value
    elif t == 'string':
        if not isinstance(value, str):
            return None, 'expected a string, got %s' % _describe(value)
        if p.choices and value not in p.choices:
            return None, 'must be one of %s (got %r)' % (', '.join(p.choices), value)
        out = value
    elif t == 'string_array':
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            return None, 'expected an array of strings, got %s' % _describe(value)
        out = list(value)
    else:  # pragma: no cover - schema error
        raise AssertionError('unknown parameter type %r' % t)
    reason = (p.check(out) if p.check else None) or _range_problem(p, out)
    return (None, reason) if reason else (out, None)


def _range_problem(p, value):
    """Why a number (or an array's element) of p is outside its documented range, or None."""
    if p.lo is None:
        return None
    values = np.atleast_1d(np.asarray(value, dtype=float))
    if values.size and (values.min() < p.lo or values.max() > p.hi):
        bad = values[(values < p.lo) | (values > p.hi)][0]
        return 'must be in %s (got %r)' % (p.range_text, float(bad) if p.type.startswith(
            'double') else int(bad))
    return None


def _describe(value):
    return '%s %r' % (type(value).__name__, value)


# --- resolving a node's parameters ---------------------------------------------------------------
def resolve(node: str, overrides: dict, staged_cones: bool = False) -> dict:
    """Merge overrides (flat dict) into node's defaults and check everything.

    Returns a flat dict of converted values (cone keys included). Raises ConfigError listing every
    problem: wrong types, failed checks, unknown parameters, cones without their parameters.
    staged_cones accepts parameters of cones not (yet) in cones.names, as a running node must while
    a user adds a cone one parameter at a time; files are read without it, to catch typos.
    """
    errors = []
    known_elsewhere = {p.name for p in SCHEMA}
    out = {}
    for p in schema_for(node):
        value, reason = check_value(p, overrides.get(p.name, p.default))
        if reason:
            errors.append((p.name, reason))
        else:
            out[p.name] = value
    names = out.get('cones.names', []) if node == CONTROLLER else []
    for name in names:
        if not CONE_NAME.match(name):
            errors.append(('cones.names', 'cone name %r must be a letter followed by letters, '
                           'digits or _' % name))
            continue
        for field_ in ('axis', 'half_angle_deg'):
            p = cone_param(name, field_)
            if p.name not in overrides:
                errors.append((p.name, 'missing (cone %r is in cones.names)' % name))
                continue
            value, reason = check_value(p, overrides[p.name])
            if reason:
                errors.append((p.name, reason))
            else:
                out[p.name] = value
    if len(set(names)) != len(names):
        errors.append(('cones.names', 'names must be unique (got %s)' % names))
    for key in overrides:
        if key in known_elsewhere:
            continue
        m = CONE_KEY.match(key)
        if m:
            if node == CONTROLLER and m.group(1) not in names and not staged_cones:
                errors.append((key, 'cone %r is not in cones.names %s' % (m.group(1), names)))
            continue
        errors.append((key, 'unknown parameter' + _suggest(key)))
    if errors:
        raise ConfigError(errors)
    return out


def _suggest(key):
    close = difflib.get_close_matches(key, list(BY_NAME), n=1)
    return ' (did you mean %r?)' % close[0] if close else ''


def change_problem(changed: Iterable[str], allowed: Sequence[str], when: str) -> Optional[str]:
    """Why changing the parameters changed is refused (a sentence naming them), or None: each
    must be one of allowed, or a parameter no node reads; when says when they may change.
    """
    refused = sorted(n for n in changed if n not in allowed
                     and (n in BY_NAME or CONE_KEY.match(n) or n == 'cones.names'))
    if not refused:
        return None
    return '%s may change %s only' % (', '.join(refused), when)


def configuration_given(node: str, names: Iterable[str]) -> bool:
    """Whether the parameters names, as given to node at start (files and -p), configure it: at
    least one of them is a parameter only this node reads (a cone, for the controller). The
    values a ``/**`` section shares with other nodes (mass, gravity, ...) do not count, so a
    node started under a name or namespace its file does not address is not configured.
    """
    return any(CONE_KEY.match(n) or n == 'cones.names'
               or (n in BY_NAME and BY_NAME[n].nodes == (node,)) for n in names)
