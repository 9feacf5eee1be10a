"""The bridge's MAVLink link over real UDP on 127.0.0.1 against bad input and strangers: a
pymavlink ground station sends garbage of each kind, then a command, and must get its answer; with
a signing key, only a station with the key is answered (no ROS: the link thread and the vehicle's
answers are what the bridge node runs).
"""
import hashlib
import os
import random
import socket
import threading
import time

import pytest

os.environ['MAVLINK20'] = '1'
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v10 import common as mav1  # noqa: E402
from pymavlink.dialects.v20 import common as mav  # noqa: E402

from geoctl_ros.mavlink import signing  # noqa: E402
from geoctl_ros.mavlink.actions import Send  # noqa: E402
from geoctl_ros.mavlink.link import Link, encoder  # noqa: E402
from geoctl_ros.mavlink.vehicle import Vehicle  # noqa: E402

TRIES = 10                     # (the parser itself gets 10,000 inputs from ./run fuzz)
ANSWER_WITHIN = 5.0            # s: no answer by then is a lost command, not a slow one


def free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


class Bridge:
    """The bridge's MAVLink half: a Link, and a thread that answers with the Vehicle."""

    def __init__(self, port, key=None):
        self.link = Link('udpin:127.0.0.1:%d' % port, 7, mav.MAV_COMP_ID_AUTOPILOT1,
                         signing=None if key is None else (key, 0, signing.now_timestamp()))
        self.vehicle = Vehicle(encoder(7, mav.MAV_COMP_ID_AUTOPILOT1), 7)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self):
        while not self._stop.is_set():
            for msg in self.link.receive():
                for action in self.vehicle.handle(msg):
                    if isinstance(action, Send):
                        self.link.send(action.message)
            time.sleep(0.002)

    def close(self):
        self._stop.set()
        self._thread.join(2.0)
        self.link.close()


@pytest.fixture
def pair():
    port = free_udp_port()
    bridge = Bridge(port)
    gcs = mavutil.mavlink_connection('udpout:127.0.0.1:%d' % port, source_system=255,
                                     source_component=190, dialect='common')
    yield bridge, gcs
    gcs.close()
    bridge.close()


def command(gcs):
    """A COMMAND_LONG the vehicle answers (UNSUPPORTED), as wire bytes. None of the garbage holds
    one that parses, so each answer belongs to the command of its try.
    """
    return gcs.mav.command_long_encode(7, 1, mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0,
                                       0).pack(gcs.mav)


def garbage(kind, gcs, rng):
    """Datagrams of one kind of bad input."""
    valid = command(gcs)
    if kind == 'random bytes':
        return [bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 300))) for _ in range(50)]
    if kind == 'truncated frames':    # a header that promises more than the datagram holds
        return [valid[:rng.randint(1, len(valid) - 1)] for _ in range(10)]
    if kind == 'wrong CRC':
        bad = bytearray(valid)
        bad[-1] ^= 0xFF
        return [bytes(bad)] * 10
    if kind == 'MAVLink 1 frames':    # valid, of the old protocol; the vehicle answers none
        v1 = mav1.MAVLink(None, srcSystem=255, srcComponent=190)
        return [v1.heartbeat_encode(6, 8, 0, 0, 0).pack(v1)] * 5
    if kind == 'oversized datagrams':  # near the UDP limit, ending in a v2 start marker and length
        return [bytes(rng.getrandbits(8) for _ in range(60000)) + b'\xfd\xff' for _ in range(3)]
    if kind == 'a flood':
        return [b'\xfd' + bytes([rng.randint(0, 255)]) for _ in range(3000)]
    raise ValueError(kind)


def drained(bridge, timeout=10.0):
    """Wait until the bridge has read whatever reached its socket: its datagram count stops
    growing (a condition, not a duration: a busy machine only makes it take longer).
    """
    last, steady, end = -1, 0, time.monotonic() + timeout
    while steady < 3 and time.monotonic() < end:
        n = bridge.link.counts['datagrams']
        steady, last = (steady + 1 if n == last else 0), n
        time.sleep(0.02)


def answer(gcs, within):
    """Seconds until the command's COMMAND_ACK arrived, or None after `within` s."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < within:
        msg = gcs.recv_match(type='COMMAND_ACK', blocking=True, timeout=0.05)
        if msg is not None and msg.command == mav.MAV_CMD_NAV_TAKEOFF:
            assert msg.result == mav.MAV_RESULT_UNSUPPORTED
            return time.monotonic() - t0
    return None


@pytest.mark.parametrize('kind', ['random bytes', 'truncated frames', 'wrong CRC',
                                  'MAVLink 1 frames', 'oversized datagrams', 'a flood'])
def test_after_bad_input_the_next_command_is_answered(pair, kind):
    bridge, gcs = pair
    rng = random.Random(kind)
    gcs.write(command(gcs))                   # the link is up: the bridge has our address
    assert answer(gcs, 5.0) is not None
    misses = []
    for k in range(TRIES):
        for datagram in garbage(kind, gcs, rng):
            gcs.write(datagram)
        # the next command comes after the bad input: a flood's backlog can fill the socket's
        # buffer, and the kernel then drops whatever comes, which no parser can answer
        drained(bridge)
        gcs.write(command(gcs))
        if answer(gcs, ANSWER_WITHIN) is None:
            misses.append(k)
    assert not misses, '%s: no answer within %.0f s in tries %s of %d (link counts %s)' % (
        kind, ANSWER_WITHIN, misses, TRIES, bridge.link.counts)
    if kind != 'MAVLink 1 frames':
        assert bridge.link.counts['bad data'] > 0


KEY = hashlib.sha256(b'lab passphrase').digest()


def ground_station(port, key=None, system=255):
    gcs = mavutil.mavlink_connection('udpout:127.0.0.1:%d' % port, source_system=system,
                                     source_component=190, dialect='common')
    if key is not None:
        gcs.setup_signing(key, sign_outgoing=True)      # and refuses unsigned frames itself
    return gcs


def test_with_a_key_only_a_station_holding_it_is_answered():
    port = free_udp_port()
    bridge = Bridge(port, KEY)
    genuine = ground_station(port, KEY)
    strangers = [ground_station(port), ground_station(port, hashlib.sha256(b'guess').digest())]
    try:
        sent = command(genuine)                 # signed by the station's signer, as captured
        genuine.write(sent)
        assert answer(genuine, 5.0) is not None           # the answer was signed: it took it
        for s in strangers:                               # unsigned, and a wrong key
            s.write(command(s))
            assert answer(s, 1.0) is None
        genuine.write(sent)                               # a replay of the captured command
        day = 24 * 3600 * 100_000                          # a forged frame from the future
        forger = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        forger.signing.secret_key = hashlib.sha256(b'guess').digest()
        forger.signing.sign_outgoing, forger.signing.link_id = True, genuine.mav.signing.link_id
        forger.signing.timestamp = signing.now_timestamp() + day
        genuine.write(command_with(forger))
        time.sleep(0.3)
        assert answer(genuine, 0.5) is None               # neither was answered
        genuine.write(command(genuine))                   # and the station is not locked out
        assert answer(genuine, 2.0) is not None
        refused = [why for why, kind, _ in bridge.link.refusals]
        assert refused == ['unsigned', 'bad signature', 'replayed', 'bad signature']
        assert all(addr[0] == '127.0.0.1' for _, _, addr in bridge.link.refusals)
        assert bridge.link.counts['refused'] == 4
    finally:
        for s in strangers + [genuine]:
            s.close()
        bridge.close()


def command_with(m):
    return m.command_long_encode(7, 1, mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 0).pack(m)
