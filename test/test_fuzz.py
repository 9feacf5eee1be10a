"""The fuzzer's short version (``./run fuzz`` runs 10,000 inputs per boundary): a few hundred
hostile inputs at each boundary, each kept by every promise (``geoctl_ros.fuzz``): nothing
escapes, nothing non-finite comes out, no motor moves, the next valid input is answered, every
refusal has a reason. Each boundary must both refuse and accept some of what it is given, so that
a strategy that stopped reaching the code under test fails here.
"""
import pytest
from tools_support import NO_EXTRA

pytest.importorskip('hypothesis', reason=NO_EXTRA)

from hypothesis import strategies as st

from geoctl_ros.fuzz.boundaries import BOUNDARIES, close_nodes
from geoctl_ros.fuzz.hostile import Tally, run_property

EXAMPLES = 100


@pytest.fixture(scope='module', autouse=True)
def nodes_closed_at_the_end():
    yield
    close_nodes()


@pytest.mark.parametrize('boundary', sorted(BOUNDARIES))
def test_hostile_input_at_each_boundary_is_refused_with_a_reason_and_nothing_breaks(boundary):
    tally = BOUNDARIES[boundary](EXAMPLES, 2)
    assert tally.crash is None, tally.line()
    assert tally.tried >= EXAMPLES
    assert 0 < tally.refused < tally.tried, tally.line()


def test_a_broken_promise_is_shrunk_to_the_smallest_input_that_breaks_it():
    """The machinery itself: a property that breaks for any integer from 1000 on is reported with
    exactly 1000, the smallest input that breaks it, and counted as a crash.
    """
    def check(n):
        if n >= 1000:
            raise ValueError('too big')
        return 'refused' if n < 0 else None
    tally = run_property(Tally('demo'), st.integers(), check, 500, 1)
    assert tally.crash is not None and 'too big' in tally.crash
    assert 'n=1000,' in tally.crash.replace('x=', 'n='), tally.crash
