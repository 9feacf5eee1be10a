"""Hypothesis's hostile values and the property runner every boundary uses."""
import contextlib
import io
import math
import time
import warnings

from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import seed as hypothesis_seed
from hypothesis import strategies as st

NOW = int(time.time())       # the stamps' "now", fixed: Hypothesis replays what it draws


HOSTILE_FLOATS = (math.nan, math.inf, -math.inf, 0.0, -0.0, 5e-324, 1e-310, 1e30, -1e30, 1.0,
                  -1.0, 0.5, 2.0 ** 31, 2.0 ** 64, 1e308)

HOSTILE_FLOAT32 = (math.nan, math.inf, -math.inf, 0.0, -0.0, 1e-45, 1e30, -1e30, 1.0, -1.0,
                   0.5, 2.0 ** 31, 3.4e38)


def hostile_float():
    return st.one_of(st.sampled_from(HOSTILE_FLOATS), st.floats())


def hostile_float32():
    """What a MAVLink float field can carry."""
    return st.one_of(st.sampled_from(HOSTILE_FLOAT32), st.floats(width=32))


class Tally:
    """What a boundary was given and what it did with it."""

    def __init__(self, name):
        self.name, self.tried, self.refused, self.crash, self.seconds = name, 0, 0, None, 0.0

    def line(self):
        return '%-11s %7d inputs tried, %7d refused, %d crash%s  (%.0f s)%s' % (
            self.name, self.tried, self.refused, 0 if self.crash is None else 1,
            '' if self.crash is not None else 'es', self.seconds,
            '' if self.crash is None else '\n  smallest failing input:\n' + self.crash)


def run_property(tally, strategy, check, examples, seed):
    """Run check on examples drawn from strategy; check returns a refusal reason (counted) or
    None, and raises on a broken promise. The first failure is shrunk and kept in tally.crash.
    """
    @settings(max_examples=examples, database=None, deadline=None, derandomize=False,
              suppress_health_check=list(HealthCheck), phases=(Phase.generate, Phase.shrink),
              print_blob=False)
    @hypothesis_seed(seed)
    @given(strategy)
    def prop(x):
        tally.tried += 1
        with warnings.catch_warnings():      # a numpy warning is a value that got too far
            warnings.simplefilter('error', RuntimeWarning)
            why = check(x)
        if why is not None:
            if not str(why).strip():
                raise AssertionError('a refusal without a reason')
            tally.refused += 1
    t0 = time.perf_counter()
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            prop()
    except Exception as e:          # the property broke: Hypothesis has shrunk it
        notes = '\n'.join(getattr(e, '__notes__', ()))     # Falsifying example: ...
        tally.crash = '%s%s\n%s: %s' % (out.getvalue(), notes, type(e).__name__, e)
    tally.seconds = time.perf_counter() - t0
    return tally


def finite_fields(msg):
    """Assert every float field of a pymavlink message is finite."""
    for name in msg.get_fieldnames():
        v = getattr(msg, name)
        for x in (v if isinstance(v, (list, tuple)) else [v]):
            if isinstance(x, float) and not math.isfinite(x):
                raise AssertionError('%s.%s is %r' % (msg.get_type(), name, x))

