"""MAVLink 2 signing, checked against pymavlink's own signer (the ground station's side): the key
file, genuine, unsigned, wrongly signed, replayed and forged frames, and the outgoing timestamp.
"""
import hashlib
import os

import pytest

os.environ['MAVLINK20'] = '1'
from pymavlink.dialects.v20 import common as mav  # noqa: E402

from geoctl_ros.mavlink import signing  # noqa: E402
from geoctl_ros.mavlink.signing import SigningKeyError, TimestampStore, Verifier  # noqa: E402

pytestmark = pytest.mark.odroid

KEY = hashlib.sha256(b'lab passphrase').digest()


def station(key=KEY, timestamp=None, link_id=1, system=255):
    """A ground station's encoder, signing as pymavlink does (mavutil's setup_signing: the
    timestamp starts at the clock).
    """
    m = mav.MAVLink(None, srcSystem=system, srcComponent=190)
    m.signing.secret_key, m.signing.sign_outgoing = key, key is not None
    m.signing.link_id = link_id
    m.signing.timestamp = signing.now_timestamp() if timestamp is None else timestamp
    return m


def arm_frame(m):
    return m.command_long_encode(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0,
                                 0).pack(m)


def test_genuine_frames_pass_and_unsigned_wrong_key_and_replayed_ones_do_not():
    v, gcs = Verifier(KEY), station()
    first = arm_frame(gcs)
    assert v.check(first) is None
    assert v.check(arm_frame(gcs)) is None                  # the next one, timestamp + 1
    assert v.check(first) == 'replayed'                      # captured and sent again
    assert v.check(arm_frame(station(key=None))) == 'unsigned'
    assert v.check(arm_frame(station(key=hashlib.sha256(b'guess').digest()))) == 'bad signature'
    tampered = bytearray(arm_frame(gcs))
    tampered[14] ^= 0x01                                     # a payload bit (the CRC aside)
    assert v.check(tampered) == 'bad signature'
    assert v.check(arm_frame(gcs)) is None
    assert v.refused == {'unsigned': 1, 'bad signature': 2, 'replayed': 1, 'too old': 0,
                         'from the future': 0}


def test_a_forged_frame_from_the_future_never_locks_the_stream_out():
    v, gcs = Verifier(KEY), station()
    assert v.check(arm_frame(gcs)) is None
    day = 24 * 3600 * 100_000
    forged = arm_frame(station(key=hashlib.sha256(b'guess').digest(),
                               timestamp=signing.now_timestamp() + day))
    assert v.check(forged) == 'bad signature'
    assert v.check(arm_frame(gcs)) is None                   # the genuine station goes on
    # pymavlink's own check, as it is: the forged frame moves the stream's timestamp first, and
    # the genuine station's next frame is then refused as a replay (why Verifier exists)
    parser, gcs2 = mav.MAVLink(None), station(timestamp=signing.now_timestamp() + 10)
    parser.signing.secret_key = KEY
    parser.parse_buffer(arm_frame(gcs2))
    assert parser.signing.goodsig_count == 1
    with pytest.raises(mav.MAVError):
        parser.decode(bytearray(forged))
    with pytest.raises(mav.MAVError, match='signature'):
        parser.decode(bytearray(arm_frame(gcs2)))


def test_streams_are_per_system_component_and_link_and_a_new_one_must_be_recent():
    now = signing.now_timestamp()
    v = Verifier(KEY, clock=lambda: now)
    a, b = station(link_id=1, timestamp=now), station(link_id=2, timestamp=now - 100)
    assert v.check(arm_frame(a)) is None
    assert v.check(arm_frame(b)) is None                     # its own stream: older is fine
    stale = station(link_id=3, timestamp=now - signing.NEW_STREAM_SLACK - 1)
    assert v.check(arm_frame(stale)) == 'too old'
    assert set(v.streams) == {(255, 190, 1), (255, 190, 2)}


def test_the_key_file_is_a_passphrase_or_64_hex_digits_and_private(tmp_path):
    f = tmp_path / 'key'
    f.write_text('lab passphrase\n')
    f.chmod(0o600)
    assert signing.load_key(str(f)) == KEY                   # SHA-256, as ground stations do
    f.write_text(KEY.hex() + '\n')
    assert signing.load_key(str(f)) == KEY                   # the raw key
    f.chmod(0o640)
    with pytest.raises(SigningKeyError, match='group or others'):
        signing.load_key(str(f))
    f.chmod(0o600)
    f.write_text('\n')
    with pytest.raises(SigningKeyError, match='empty'):
        signing.load_key(str(f))
    with pytest.raises(SigningKeyError, match='No such file'):
        signing.load_key(str(tmp_path / 'missing'))


def test_the_outgoing_timestamp_never_goes_backwards_across_restarts(tmp_path):
    store = TimestampStore(str(tmp_path / 'signing.timestamp'))
    t0 = store.start()
    assert abs(t0 - signing.now_timestamp()) < 100_000       # the clock, when nothing was saved
    ahead = signing.now_timestamp() + 3600 * 100_000         # the last run signed past the clock
    store.save(ahead)
    assert store.start() == ahead + 1                        # the clock went back: keep going
    assert oct(os.stat(store.path).st_mode & 0o777) == '0o600'


def test_a_frame_from_the_future_is_refused_and_never_moves_its_stream():
    """Issue (hostile input): a validly signed frame dated a year ahead was accepted, and the
    genuine station's next frames on its stream were then refused as replays until a restart.
    """
    v, gcs = Verifier(KEY), station()
    assert v.check(arm_frame(gcs)) is None
    year = 365 * 24 * 3600 * 100_000
    ahead = station(timestamp=signing.now_timestamp() + year)         # the key, a wrong clock
    assert v.check(arm_frame(ahead)) == 'from the future'
    assert v.check(arm_frame(gcs)) is None                            # the genuine one goes on
    within = station(timestamp=signing.now_timestamp() + signing.FUTURE_SLACK // 2, link_id=4)
    assert v.check(arm_frame(within)) is None                         # a clock a little ahead
    assert v.refused['from the future'] == 1


def test_a_frame_captured_before_a_restart_is_still_a_replay_after_it(tmp_path):
    """Issue (hostile input): incoming stream timestamps lived in memory only, so after a restart
    a captured ARM up to a minute old was accepted again. They are saved as the outgoing one is.
    """
    store = signing.StreamStore(str(tmp_path / 'signing.timestamp.streams'))
    v, gcs = Verifier(KEY), station()
    captured = arm_frame(gcs)
    assert v.check(captured) is None
    assert v.check(arm_frame(gcs)) is None
    store.save(v.streams.copy())
    assert oct(os.stat(store.path).st_mode & 0o777) == '0o600'
    restarted = Verifier(KEY, streams=store.load())
    assert restarted.check(captured) == 'replayed'
    assert restarted.check(arm_frame(gcs)) is None                    # the station goes on
    assert Verifier(KEY).check(captured) is None      # (what a restart without them accepted)
    (tmp_path / 'bad').write_text('1 2 x 4\n255 190 1 12\n\n')
    assert signing.StreamStore(str(tmp_path / 'bad')).load() == {(255, 190, 1): 12}
