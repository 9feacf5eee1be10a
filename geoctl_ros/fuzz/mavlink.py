"""The ``mavlink`` boundary: random datagrams, valid frames with hostile fields, and signed frames
at random timestamps and link ids, through the link's parser, signature check and vehicle handler.
"""

from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mav  # (the v2 dialect itself: MAVLink 2)

from geoctl_ros.fuzz.hostile import (
    NOW,
    Tally,
    finite_fields,
    hostile_float32,
    run_property,
)
from geoctl_ros.mavlink.actions import Arm, Ignored, MotorTest, Send, SetParameter
from geoctl_ros.mavlink.link import encoder, parse_datagram
from geoctl_ros.mavlink.signing import Verifier
from geoctl_ros.mavlink.vehicle import Vehicle

# --- MAVLink -----------------------------------------------------------------------------------
KEY = bytes(range(32))


COMMANDS = (mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_CMD_DO_MOTOR_TEST,
            mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 0, 65535)


@st.composite
def mavlink_frames(draw):
    """(datagram bytes, signed with the key?)."""
    kind = draw(st.sampled_from(('bytes', 'command', 'param_set', 'param_read', 'other',
                                 'signed')))
    if kind == 'bytes':
        return draw(st.binary(max_size=300)), False
    gcs = mav.MAVLink(None, srcSystem=draw(st.integers(0, 255)),
                      srcComponent=draw(st.integers(0, 255)))
    gcs.WIRE_PROTOCOL_VERSION = '2.0'
    signed = kind == 'signed' or draw(st.booleans())
    if signed:
        gcs.signing.secret_key = KEY
        gcs.signing.sign_outgoing = True
        gcs.signing.link_id = draw(st.integers(0, 255))
        now = (NOW - 1420070400) * 100_000
        gcs.signing.timestamp = draw(st.one_of(
            st.integers(0, 2 ** 48 - 1), st.integers(now - 10 ** 7, now + 10 ** 7)))
    target = draw(st.sampled_from((0, 1, 2, 255)))
    f = hostile_float32
    if kind in ('command', 'signed'):
        msg = gcs.command_long_encode(target, 1, draw(st.sampled_from(COMMANDS)), 0,
                                      *[draw(f()) for _ in range(7)])
    elif kind == 'param_set':
        name = draw(st.one_of(st.sampled_from(('GC_K_R', 'GC_POSE_TO', 'GC_ADAPTIVE', 'GC_MASS')),
                              st.text(max_size=16)))
        msg = gcs.param_set_encode(target, 1, name.encode('utf-8')[:16], draw(f()),
                                   draw(st.integers(0, 255)))
    elif kind == 'param_read':
        msg = gcs.param_request_read_encode(target, 1, draw(st.binary(max_size=16)),
                                            draw(st.integers(-32768, 32767)))
    else:
        msg = draw(st.sampled_from((
            gcs.param_request_list_encode(target, 1),
            gcs.mission_request_list_encode(target, 1, draw(st.integers(0, 255))),
            gcs.setup_signing_encode(target, 1, [0] * 32, 0),
            gcs.heartbeat_encode(draw(st.integers(0, 255)), 0, 0, 0, 0))))
    data = bytearray(msg.pack(gcs))
    if draw(st.booleans()):                      # a flipped byte or a cut
        if draw(st.booleans()) and data:
            i = draw(st.integers(0, len(data) - 1))
            data[i] ^= draw(st.integers(1, 255))
        else:
            data = data[:draw(st.integers(0, len(data)))]
    return bytes(data), signed


def fuzz_mavlink(examples, seed):
    verifier = Verifier(KEY)
    parser, out_mav = encoder(1, 1), encoder(1, 1)
    vehicle = Vehicle(encoder(1, 1), 1)

    def check(frame):
        data, _ = frame
        msgs, bad = parse_datagram(parser, data)
        why = 'bad data' if bad else None
        for m in msgs:
            if m.get_type() == 'BAD_DATA' or m.get_type().startswith('UNKNOWN'):
                why = 'bad data'
                continue
            refusal = verifier.check(m.get_msgbuf())
            if refusal is not None:
                why = refusal
            for action in vehicle.handle(m):
                if isinstance(action, Send):
                    out = action.message
                    finite_fields(out)
                    out.pack(out_mav)
                    if out.get_type() == 'COMMAND_ACK' and out.result in (
                            mav.MAV_RESULT_DENIED, mav.MAV_RESULT_UNSUPPORTED,
                            mav.MAV_RESULT_TEMPORARILY_REJECTED):
                        why = why or 'command refused'
                    if out.get_type() == 'STATUSTEXT':
                        why = why or out.text
                elif isinstance(action, Ignored):
                    why = why or action.why
                elif isinstance(action, MotorTest):
                    assert isinstance(action.rotor, int) and 1 <= action.rotor <= 32, action
                    assert 0.0 <= action.command <= 1.0, action
                    assert 0.0 < action.seconds <= 10.0, action
                elif isinstance(action, Arm):
                    assert isinstance(action.on, bool), action
                elif isinstance(action, SetParameter):
                    assert isinstance(action.value, float), action
                else:
                    raise AssertionError('unknown action %r' % (action,))
        return why
    return run_property(Tally('mavlink'), mavlink_frames(), check, examples, seed)

