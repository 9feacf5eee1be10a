"""The ESC driver on a recording bus (no rclpy, no hardware): the protocol's bytes, zero at start
and stop, the watchdog, NACKs and missing ESCs, the motor test; and the virtual ESC bus.
"""
import dataclasses

from diagnostic_msgs.msg import KeyValue
import numpy as np
import pytest
from sensor_msgs.msg import JointState

from geoctl_ros.core.actuation.esc_wire import ArmedState, EscHealth, esc_report, esc_report_of
from geoctl_ros.esc import health, protocol
from geoctl_ros.esc.bus import RecordingBus
from geoctl_ros.esc.driver import EscDriver, EscStartError
from geoctl_ros.esc.virtual import VirtualEscBus
from geoctl_ros.nodes.conversions import (
    armed_state_msg,
    armed_state_of,
    commands_of,
    motor_commands_msg,
    session_of,
)
from geoctl_ros.params.esc import EscConfig

pytestmark = pytest.mark.odroid

LAB = (0x29, 0x2A, 0x2B, 0x2C, 0x2D, 0x2E)
HOVER = [0.49] * 6


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


SESSION = 0x5EC0


def driver(present=LAB, armed=True, **kw):
    """A driver on a recording bus, following an armed controller of SESSION (or disarmed)."""
    clock = Clock()
    bus = RecordingBus(present, clock)
    d = EscDriver(EscConfig(LAB, 240, probe_timeout=0.0, **kw), bus, clock)
    d.follow(armed, SESSION)
    return d, bus, clock


def test_only_the_armed_controllers_session_moves_a_motor():
    """The gate (issue: the ESCs obeyed any publisher): disarmed, the controller's own non-zero
    commands write zero; a message of another session or none (a plain publisher, a recorded
    flight) is refused, counted, and leaves the controller's command in force.
    """
    d, bus, clock = driver(armed=False)
    d.start()
    assert d.offer(HOVER, session=SESSION) is None
    d.write()
    assert set(written(bus)[LAB[0]][-1:]) == {b'\x00'}
    d.follow(True, SESSION)
    assert d.offer(HOVER, session=SESSION) is None
    d.write()
    hover = d.output.tolist()
    assert min(hover) > 0.48
    for other in (0, SESSION + 1):
        assert 'not from the controller' in d.offer([0.9] * 6, session=other)
    d.write()
    assert d.output.tolist() == hover and d.foreign == 2
    d.follow(False, SESSION)
    d.write()
    assert d.output.tolist() == [0.0] * 6


def written(bus, since=0):
    """{address: [bytes, ...]} of the writes from number `since` on."""
    out = {}
    for _, a, data in list(bus.writes)[since:]:
        out.setdefault(a, []).append(data)
    return out


def test_the_set_points_are_encoded_as_the_protocol_says():
    c = [0.0, 118 / 240, 1.0, 0.5, 1e-9, 0.9999]
    assert protocol.encode(c, 240) == [bytes((v,)) for v in (0, 118, 240, 120, 0, 240)]
    # 11 bits: sp = c * 240 * 8, written as sp / 8 then sp % 8
    eleven = protocol.encode([118.375 / 240, 1.0, 0.0], 240, resolution=11)
    assert eleven == [bytes((118, 3)), bytes((240, 0)), bytes((0, 0))]
    for data in eleven + protocol.encode(c, 240):
        again = protocol.encode([protocol.decode(data, 240)], 240, len(data) * 3 + 5)
        assert again == [data]
    # telemetry: 0.1 A to 20 A, then 1 A steps; the state byte's meanings
    assert protocol.parse(bytes((15, 255, 41))) == protocol.Telemetry(1.5, 255, 41.0)
    assert protocol.current_amps(201) == 21.0 and np.isnan(protocol.current_amps(255))
    assert [protocol.current_amps(protocol.current_raw(a)) for a in (0.0, 7.3, 35.0)] == [
        0.0, 7.3, 35.0]
    assert protocol.state_problem(255)[0] == protocol.OK
    assert protocol.state_problem(39) == (protocol.ERROR, 'start failed')
    assert protocol.state_problem(7) == (protocol.ERROR, 'self-test error 7')
    assert protocol.state_problem(120)[0] == protocol.WARN
    with pytest.raises(ValueError, match='2 bytes'):
        protocol.parse(b'\x01\x02')


def test_zero_is_written_to_every_esc_at_start_and_at_stop():
    d, bus, clock = driver()
    d.start()
    assert {a: v[0] for a, v in written(bus).items()} == {a: b'\x00' for a in LAB}
    d.offer(HOVER)
    d.write()
    assert all(v == [b'\x76'] for v in written(bus, 6).values())       # 0.49 * 240 = 118
    n = len(bus.writes)
    assert d.stop() == []
    assert {a: v for a, v in written(bus, n).items()} == {a: [b'\x00'] for a in LAB}


def test_the_watchdog_gives_zero_after_the_timeout_and_after_a_malformed_command():
    d, bus, clock = driver(timeout=0.1)
    d.start()
    assert d.write() == 'no command yet' and not d.output.any()
    d.offer(HOVER)
    clock.t += 0.1                              # exactly the timeout: still in force
    assert d.write() == 'commanded' and bus.last(0x29) == b'\x76'
    clock.t += 0.001
    assert d.write().startswith('commands stale') and bus.last(0x29) == b'\x00'
    d.offer(HOVER)
    assert d.write() == 'commanded'
    for bad, why in (([0.5] * 5, 'expected 6 finite values'), ([np.nan] * 6, 'finite'),
                     ([1.5] * 6, 'outside [0, 1]'), ([-0.1] + [0.5] * 5, 'outside [0, 1]')):
        assert why in d.offer(bad)
        assert d.write() == 'refused: ' + d.refusal          # at once, not after the timeout
        assert all(bus.last(a) == b'\x00' for a in LAB)
        d.offer(HOVER)
        d.write()
    assert d.refused == 4


def test_a_nack_is_retried_and_counted_by_address_and_a_missing_esc_stops_the_start():
    d, bus, clock = driver()
    d.start()
    d.offer(HOVER)
    bus.fail(0x2B, 'nack', 2)                   # two NACKs: the second retry gets through
    bus.fail(0x2C, 'timeout', 5)                # more than the retries: this cycle misses it
    d.write()
    assert d.errors[2] == dict(nack=2, timeout=0, io=0) and bus.last(0x2B) == b'\x76'
    assert d.errors[3]['timeout'] == 3 and bus.last(0x2C) == b'\x00'    # still the start's zero
    d.write()
    assert bus.last(0x2C) == b'\x76'
    bus.stuck.add(0x2E)                          # an ESC holding the bus: the others fly on
    d.offer([0.3] * 6)
    d.write()
    assert d.errors[5]['timeout'] == 3 and bus.last(0x2E) == b'\x76'
    assert [bus.last(a) for a in LAB[:5]] == [bytes((72,))] * 5
    # an ESC that does not answer at start: refused with its rotor and address ...
    d, bus, _ = driver(present=LAB[:4] + LAB[5:])
    with pytest.raises(EscStartError, match='rotor 5 at 0x2d did not answer .*nack'):
        d.start()
    # ... unless its rotor is ignored: then it is never written, and cannot be tested
    d, bus, clock = driver(present=LAB[:4] + LAB[5:], ignore=frozenset({5}))
    d.start()
    d.offer(HOVER)
    d.write()
    assert 0x2D not in written(bus) and len(written(bus)) == 5
    clock.t += 1.0
    assert 'missing' in d.start_test(5, 0.1, 1.0, armed=False)


def test_the_motor_test_is_refused_while_armed_or_commanded_and_ends_by_itself():
    d, bus, clock = driver()
    d.start()
    assert d.start_test(2, 0.1, 1.0, armed=True) == 'refused: the controller is armed'
    d.offer(HOVER)
    assert 'motor_commands are arriving' in d.start_test(2, 0.1, 1.0, armed=False)
    clock.t += 0.2                                          # the commands went stale
    assert 'outside [0, 0.3]' in d.start_test(2, 0.5, 1.0, armed=False)
    assert 'no rotor 7' in d.start_test(7, 0.1, 1.0, armed=False)
    assert d.start_test(2, 0.1, 1.0, armed=False) is None
    assert 'runs for 1.0 s more' in d.start_test(3, 0.1, 1.0, armed=False)
    assert d.write() == 'motor test of rotor 2'
    assert [bus.last(a) for a in LAB] == [b'\x00', b'\x18', b'\x00', b'\x00', b'\x00', b'\x00']
    clock.t += 1.0
    assert d.write() == 'no command yet' or d.write().startswith('commands stale')
    assert bus.last(0x2A) == b'\x00'
    # a command during a test ends it at once
    assert d.start_test(1, 0.1, 5.0, armed=False) is None
    d.offer(HOVER)
    assert d.write() == 'commanded' and d.test is None


def test_a_disarmed_controllers_zeros_leave_a_motor_test_running_and_its_first_command_ends_it():
    """The controller publishes zeros every tick while disarmed: a motor test beside it runs.
    When it arms, its armed state and its first command travel on two topics; the command may
    come first (a CI flight saw a test start just after arming): it ends the test, and a test
    asked for then is refused, though this node has not heard the arming yet.
    """
    d, bus, clock = driver(armed=False)
    d.start()
    d.offer([0.0] * 6)
    assert d.start_test(2, 0.1, 1.0, armed=False) is None
    for _ in range(5):
        clock.t += 0.01
        d.offer([0.0] * 6)
        assert d.write() == 'motor test of rotor 2'
    d.offer(HOVER)                                 # armed; the armed state not here yet
    assert d.test is None and d.write() == 'commanded'
    assert [bus.last(a) for a in LAB] == [b'\x00'] * 6     # not armed here: zero, not the test
    assert 'motor_commands are arriving' in d.start_test(2, 0.1, 1.0, armed=False)


def test_the_telemetry_is_read_round_robin():
    d, bus, clock = driver()
    d.start()
    bus.telemetry[0x2A] = bytes((31, 39, 72))
    seen = [d.read_next() for _ in range(6)]
    assert sorted(seen) == list(range(6))
    assert d.telemetry[1] == protocol.Telemetry(3.1, 39, 72.0)


def test_the_virtual_bus_carries_the_bytes_between_processes_views(tmp_path):
    path = str(tmp_path / 'bus')
    node_side, sim_side = VirtualEscBus(path, LAB), VirtualEscBus(path, LAB)
    d = EscDriver(EscConfig(LAB, 240, probe_timeout=0.0), node_side)
    with pytest.raises(EscStartError, match='rotor 1 at 0x29'):
        d.start()                                           # the sim has not powered them
    sim_side.power(True)
    d.start()
    d.follow(True, SESSION)
    d.offer(HOVER)
    d.write()
    got = sim_side.setpoints()
    assert [protocol.decode(b, 240) for b, _ in got] == [118 / 240] * 6
    sim_side.answer(2, protocol.current_raw(4.2), 255, 38.0)
    d._read(2)
    assert d.telemetry[2] == protocol.Telemetry(4.2, 255, 38.0)
    log = sim_side.log()
    assert len(log) == 12 and set(log['address'][:6]) == set(LAB)
    assert list(log['b0'][6:]) == [118] * 6 and np.all(np.diff(log['t']) >= 0)
    with pytest.raises(ValueError, match='not a virtual ESC bus of 4'):
        VirtualEscBus(path, LAB[:4])


def test_the_diagnostics_say_what_is_wrong_with_which_esc():
    d, bus, clock = driver()
    d.start()
    d.offer(HOVER)
    clock.t += 0.004
    d.write()
    r = health.report(d, clock.t, 80.0, 100.0)
    assert r.level == protocol.OK and r.message == 'ESCs commanded'
    lat = r.figures.latency
    assert lat is not None and lat.max == pytest.approx(0.004)   # receipt -> bus
    bus.telemetry[0x2A] = bytes((31, 7, 40))                     # self-test error
    bus.telemetry[0x2B] = bytes((31, 120, 85))                   # limiting, and hot
    for _ in range(6):
        d.read_next()
    bus.present.discard(0x2C)                                    # rotor 4 stops answering
    clock.t += 1.0
    d.offer(HOVER)
    d.write()
    r = health.report(d, clock.t, 80.0, 100.0)
    assert r.level == protocol.ERROR
    assert 'ESC 2 (0x2a) self-test error 7' in r.message
    assert 'ESC 4 (0x2c) does not answer' in r.message
    # what the controller reads of it (esc_health): rotor 2 at fault, rotor 4 lost
    H = EscHealth
    escs = health.esc_health(d, clock.t, 100.0)
    assert escs == (H.OK, H.FAULT, H.OK, H.LOST, H.OK, H.OK)
    # as it travels (esc_health's key-values), and as the controller reads them back
    report = esc_report(d.config.command_max, escs)
    assert report.failing and report.message == 'rotor 2 FAULT, rotor 4 LOST'
    assert report.values[:3] == (('command_max', str(d.config.command_max)), ('rotor 1', 'OK'),
                                 ('rotor 2', 'FAULT'))
    assert esc_report_of(report.values) == (d.config.command_max,
                                            ['OK', 'FAULT', 'OK', 'LOST', 'OK', 'OK'])
    assert esc_report_of(report.values[1:]) == 'no command_max'
    assert esc_report_of((('command_max', '2.5'),)) == "command_max '2.5' is not a whole number"
    assert esc_report_of(report.values[:2] + report.values[3:]) == (
        "keys other than command_max and rotor 1 ... rotor 1: 'rotor 3', 'rotor 4', 'rotor 5', "
        "'rotor 6'")
    assert not esc_report(255, (H.OK, H.IGNORED)).failing
    assert r.figures.i2c_errors == 3                             # the write and its 2 retries
    warn = health.report(d, clock.t, 80.0, 100.0, errors_before=0)
    assert warn.level == protocol.ERROR                          # the worst decides
    back = health.from_values(health.to_values(r.figures) + [('someone', 'else')])
    # the codec round trip (the latency to the microsecond it is published in)
    assert back == dataclasses.replace(r.figures, latency=back.latency)
    assert np.allclose(back.latency, r.figures.latency, rtol=0, atol=1e-6)
    escs = back.escs
    assert back.output == 'commanded' and back.set_points == tuple(HOVER)
    assert back.i2c_errors == 3
    assert escs[1] == '0x2a: 3.1 A, self-test error 7, 40 C, 0 errors'
    assert 'limited by temperature or current' in escs[2] and '85 C' in escs[2]
    assert 'no answer for 1.0 s' in escs[3]
    # a refused command on healthy ESCs: WARN, saying why
    d, bus, clock = driver()
    d.start()
    d.offer([np.nan] * 6)
    d.write()
    r = health.report(d, clock.t, 80.0, 100.0)
    assert r.level == protocol.WARN and r.figures.refused == 1
    assert r.message.startswith('motor_commands refused: expected 6 finite values')
    assert r.figures.output.startswith('refused: expected 6 finite values')


def test_the_armed_state_and_the_commands_session_travel_in_typed_fields_and_garbage_is_none():
    """~/armed is a DiagnosticStatus with the key-values armed and session; a motor command is a
    JointState with the session in its header's frame_id. What is not exactly that (a plain
    publisher's command, a session out of 32 bits, digits that are not ASCII, a third key) reads
    as no session, or no armed state, never as an exception.
    """
    for state in (ArmedState(True, 1), ArmedState(False, 2 ** 32 - 1), ArmedState(True, SESSION)):
        assert armed_state_of(armed_state_msg(state)) == state
    msg = armed_state_msg(ArmedState(True, SESSION))
    for values in ([('armed', 'true')], [('armed', 'yes'), ('session', '5')],
                   [('armed', 'true'), ('session', '0')],
                   [('armed', 'true'), ('session', '4294967296')],
                   [('armed', 'true'), ('session', '\u00b2')],
                   [('armed', 'true'), ('session', '-5')],
                   [('armed', 'true'), ('session', '5'), ('other', '1')]):
        msg.values = [KeyValue(key=k, value=v) for k, v in values]
        assert armed_state_of(msg) is None, values
    cmd = motor_commands_msg(SESSION, 6)
    cmd.effort = HOVER
    assert session_of(cmd) == SESSION and list(commands_of(cmd)) == HOVER
    assert list(cmd.name) == ['rotor %d' % i for i in range(1, 7)]
    for frame_id in ('', '0', ' 77', '\u00b2', '4294967296', '99999999999', 'session 77'):
        cmd.header.frame_id = frame_id
        assert session_of(cmd) == 0, frame_id
    assert session_of(JointState(effort=HOVER)) == 0           # a hand-typed command
    # and the driver takes a session-0 command for none of its controller's
    d, bus, clock = driver()
    assert 'not from the controller' in d.offer(HOVER, session=session_of(JointState()))
