"""docs/operator.md against the code: every message the controller, the ESC node and the MAVLink
bridge can show an operator (on /diagnostics, in an arming, set-point, service or ground-station
reply, in a log line at WARN or above), collected from the source, has a row there that says what
to do, and so has every diagnostics key (operator_support.py says how).
"""
import operator_support as ref
import pytest

pytestmark = pytest.mark.odroid


@pytest.fixture(scope='module')
def collector():
    return ref.collect()


@pytest.fixture(scope='module')
def reference():
    return ref.rows(open(ref.OPERATOR_MD).read())


def _listed(templates, collector=None):
    lines = []
    for t in templates:
        where = '' if collector is None else '  (%s)' % ', '.join(sorted(
            {'%s:%d' % (s.path, s.line) for s in collector.found[t]}))
        lines.append('  %s%s' % (ref.shown(t), where))
    return '\n'.join(lines)


def test_every_message_of_the_code_has_a_row_that_says_what_to_do(collector, reference):
    missing = ref.missing(collector.found, reference)
    assert not missing, ('%d message(s) of the code have no row with an action (and a level) in '
                         'docs/operator.md:\n%s' % (len(missing), _listed(missing, collector)))


def test_every_diagnostics_key_has_a_row_that_says_what_to_do(reference):
    missing = ref.missing(ref.diagnostics_keys(), reference, keys=True)
    assert not missing, ('%d diagnostics key(s) have no row with an action in a key table of '
                         'docs/operator.md:\n%s' % (len(missing), _listed(missing)))


def test_every_row_shows_a_message_or_key_of_the_code(collector, reference):
    """The other way round: a row's message that the code no longer says (renamed, gone) is
    reported, so the reference does not keep what the nodes stopped saying.
    """
    unknown = ref.unknown_spans(collector.found, ref.diagnostics_keys(), reference)
    assert not unknown, ('rows of docs/operator.md that show nothing the code says:\n  '
                         + '\n  '.join(unknown))


def test_every_sink_that_passes_a_sentence_on_is_accounted_for(collector):
    """A log line, reply or status whose text is made elsewhere names where (FORWARDED); a new
    one fails here until its origin is a sink or a producer the collector reads.
    """
    assert not collector.unexplained, (
        'text made where the collector does not look: add the function that makes it to '
        'PRODUCERS (its file to SOURCES), or the site to FORWARDED (operator_support.py):\n  '
        + '\n  '.join(collector.unexplained))
    assert not collector.stale_forwarded, ('FORWARDED entries that name no site any more: %s'
                                           % collector.stale_forwarded)


def test_the_collector_finds_what_the_nodes_are_known_to_say(collector):
    """A few messages of each kind of sink and producer, as the code spells them (a collector
    that finds nothing must not pass the check above).
    """
    found = set(collector.found)
    W = ref.W
    for t in ('arming refused: ' + W,                                   # ArmResult
              'angular velocity refused: %s (%s so far)' % (W, W),       # a stream's name
              'pose refused: ' + W,                                      # a log line
              'stamp %s is not newer than the last accepted %s' % (W, W),   # Stream.offer
              'non-finite control output',                      # failsafe(m), a constant
              'failsafe: ' + W,                                 # failsafe's own format
              "the IMU's specific force is %s m/s^2 at rest, not about %s: no accelerometer "
              'data in linear_acceleration, or its units wrong' % (W, W),
              'parameters not applied: ' + W, 'esc_health refused: ' + W, 'no command_max',
              'monitoring topics not published: %s: %s' % (W, W),
              'ESC %s (0x%s) does not answer' % (W, W),                  # the ESC node
              'refused: the controller is armed', 'zero not written to 0x' + W,
              'no ground station heartbeat', 'arm: the controller is not reachable'):   # bridge
        assert t in found, ref.shown(t)
    assert len(found) > 120
    assert not any(t.startswith('imu refused: ') and t.endswith('so far)') for t in found)


PLANTED = """
from geoctl_ros.core.telemetry.diagnostics import failsafe

ALARM = 'a planted constant alarm'


class Node:
    def _on_thing(self, msg):
        problem = self.loop.offer(msg)
        if problem:
            self.get_logger().warning('pose refused: ' + problem)      # documented
            self.get_logger().error('a planted log line at %.1f Hz' % 3.0)
        self.get_logger().info('a planted info line')                  # INFO: not collected
        self.get_logger().warning(ALARM)

    def _on_arm(self, request, response):
        response.message = f'planted reply {request.data}'
        return response

    def planted_problem(self, x):
        if x:
            return 'planted problem %d' % x
        notes = []
        notes.append('planted note')
        notes.append(self.made_in_a_file_not_read)
        self.disarm(failsafe('planted failsafe'))
        self.get_logger().warning(self.loop.unexplained_text)
        return None
"""


def test_a_planted_message_is_reported_missing(reference):
    """The same collector over a planted module: each undocumented message is reported, at once;
    a documented one and an INFO line are not; a log line, and a composer's item, whose text is
    made elsewhere are reported as unexplained.
    """
    module = ref.Module('nodes/planted.py', PLANTED)
    diagnostics = 'core/telemetry/diagnostics.py'        # (failsafe's body)
    c = ref.Collector(
        [module, ref.Module(diagnostics, open(ref.package_path(diagnostics)).read())],
        {'nodes/planted.py': ('Node.planted_problem',)},
        composers={('nodes/planted.py', 'Node.planted_problem')})
    c.collect()
    missing = [ref.shown(t) for t in ref.missing(c.found, reference)]
    assert missing == ['a planted constant alarm', 'a planted log line at ... Hz',
                       'planted failsafe', 'planted note', 'planted problem ...',
                       'planted reply ...'], missing
    assert sorted(c.unexplained) == [
        'nodes/planted.py:25 producer Node.planted_problem: self.made_in_a_file_not_read',
        'nodes/planted.py:27 log: self.loop.unexplained_text'], c.unexplained


def test_a_row_without_an_action_does_not_count():
    text = ('| message | level | meaning | what to do |\n|---|---|---|---|\n'
            '| `pose refused: ...` | WARN | a sample refused | |\n'
            '| `no pose received yet` | | no input | check the driver |\n'
            '| `arming refused: ...` | WARN | not armed | read the reasons |\n\n'
            '| key | example | what to do |\n|---|---|---|\n'
            '| `ticks` | `50` | |\n| `esc 1` ... `esc 6` | `0x29: ...` | see docs/esc.md |\n')
    rows = ref.rows(text)
    W = ref.W
    assert ref.missing(['pose refused: ' + W, 'no pose received yet',
                        'arming refused: ' + W], rows) == ['no pose received yet',
                                                          'pose refused: ' + W]
    assert ref.missing(['ticks', 'esc' + ' ' + W, 'arming refused: ' + W], rows, keys=True) == [
        'arming refused: ' + W, 'ticks']


def test_templates_and_spans_match_where_some_text_matches_both():
    W = ref.W
    assert ref.compatible('pose stale (last %s s ago, timeout %s s)' % (W, W),
                          'pose stale (last 0.150 s ago, timeout 0.100 s)')
    assert ref.compatible('pose stale (last %s s ago, timeout %s s)' % (W, W), 'pose stale ' + W)
    assert not ref.compatible('angular velocity refused: %s (%s so far)' % (W, W),
                              'imu refused: ' + W)
    assert not ref.compatible('armed', 'armed, all inputs fresh')
    assert ref.compatible('sensor entered cone %s, %s deg deep' % (W, W),
                          "sensor entered cone 'obstacle', " + W)
    # a template that begins with a field: its first words must stand in the span as written
    assert ref.compatible(W + ' refused: ' + W, 'pose stale ' + W)
    assert not ref.shows('pose stale ' + W, W + ' refused: ' + W)
    assert ref.shows('GC_K_R refused: ' + W, W + ' refused: ' + W)
    assert ref.shows('no configuration given for ' + W,
                     'no configuration given for %s: no parameter file (...)' % W)
