"""MAVLink 2 message signing: the key, the check of incoming frames, the outgoing timestamp.

The signing spec (mavlink.io, "Message signing"): a signed MAVLink 2 frame has incompat flag 0x01
and ends in 13 bytes, link id (1), timestamp (6, little-endian, 10 us units since
2015-01-01 00:00 UTC) and signature (6): the first 48 bits of SHA-256(key + the frame up to and
including the timestamp). A frame is accepted when its signature is the key's and its timestamp
is newer than the last accepted one of its stream (system, component, link id); a stream not seen
yet must be no more than a minute behind this side's clock, and no frame may be more than a
minute ahead of it (``FUTURE_SLACK``): a validly signed frame dated a year ahead, from a station
whose clock is wrong, would otherwise move its stream a year on and lock the genuine frames out as
replays. The last accepted timestamp of each stream is kept across restarts (``StreamStore``),
as the outgoing one is, so a frame captured before a restart is still a replay after it.

pymavlink 2.4.50's own check (``MAVLink.check_signature``) stores a stream's timestamp before it
verifies the signature, so one forged frame with a timestamp in the future makes every later
genuine frame of that stream look like a replay. ``Verifier`` checks the signature first and moves
a stream's timestamp only on a frame that passed. No rclpy, no I/O but the key and timestamp files.
"""
import hashlib
import hmac
import os
import re
import stat
import time

SIGNED = 0x01                       # incompat flag
SIGNATURE_LEN = 13                  # link id, timestamp, signature
EPOCH = 1420070400                  # 2015-01-01 00:00:00 UTC, the signing clock's zero
NEW_STREAM_SLACK = 60 * 100_000     # a new stream may be a minute behind us (10 us units)
FUTURE_SLACK = 60 * 100_000         # and no frame more than a minute ahead of us
MAX_STREAMS = 256                   # streams remembered (the oldest is forgotten past this)
# what an unsigned peer may still send when a key is set: nothing that changes anything
UNSIGNED_ALLOWED = frozenset({'HEARTBEAT', 'RADIO_STATUS'})


class SigningKeyError(ValueError):
    """A key file that cannot be used (its path and why)."""


def load_key(path):
    """The 32-byte key of a key file: 64 hex digits are the key itself; anything else is a
    passphrase (its first line, stripped), whose SHA-256 is the key, as QGroundControl and
    MAVProxy derive it. Refused when group or others may read or write the file.
    """
    try:
        st = os.stat(path)
        with open(path, 'rb') as fh:
            data = fh.read()
    except OSError as e:
        raise SigningKeyError('%s: %s' % (path, e.strerror)) from None
    if st.st_mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise SigningKeyError('%s: readable or writable by group or others (mode %03o): '
                              'chmod 600 it' % (path, stat.S_IMODE(st.st_mode)))
    text = data.decode('utf-8', 'replace').strip()
    if re.fullmatch(r'[0-9a-fA-F]{64}', text):
        return bytes.fromhex(text)
    passphrase = text.splitlines()[0].strip() if text else ''
    if not passphrase:
        raise SigningKeyError('%s: empty (write a passphrase or 64 hex digits)' % path)
    return hashlib.sha256(passphrase.encode('utf-8')).digest()


def now_timestamp(now=None):
    """This side's signing clock: 10 us units since 2015-01-01 (UTC)."""
    return int((max(time.time() if now is None else now, EPOCH) - EPOCH) * 100_000)


def signature(key, frame_without_signature):
    """The 6-byte signature of a frame up to and including its timestamp."""
    return hashlib.sha256(key + bytes(frame_without_signature)).digest()[:6]


class Verifier:
    """Checks incoming frames against the key; counts what it refused and why."""

    def __init__(self, key, clock=now_timestamp, streams=None):
        """streams: the last accepted timestamps of a previous run (``StreamStore.load``)."""
        self._key = key
        self._clock = clock
        # (system, component, link id) -> last accepted timestamp
        self.streams = dict(streams or {})
        self.refused = {'unsigned': 0, 'bad signature': 0, 'replayed': 0, 'too old': 0,
                        'from the future': 0}

    def check(self, frame):
        """None if frame (the whole wire bytes of one message) is signed with the key and new;
        else why not (and counted).
        """
        frame = bytes(frame)
        if len(frame) < 10 + SIGNATURE_LEN or frame[0] != 0xFD or not frame[2] & SIGNED:
            return self._refuse('unsigned')
        body, link_id = frame[:-6], frame[-13]
        timestamp = int.from_bytes(frame[-12:-6], 'little')
        if not hmac.compare_digest(signature(self._key, body), frame[-6:]):
            return self._refuse('bad signature')
        stream = (frame[5], frame[6], link_id)          # system, component, link
        last = self.streams.get(stream)
        if last is not None and timestamp <= last:
            return self._refuse('replayed')
        now = self._clock()
        if last is None and timestamp < now - NEW_STREAM_SLACK:
            return self._refuse('too old')
        if timestamp > now + FUTURE_SLACK:
            return self._refuse('from the future')
        self.streams.pop(stream, None)
        self.streams[stream] = timestamp                # only after the signature passed
        while len(self.streams) > MAX_STREAMS:
            self.streams.pop(next(iter(self.streams)))
        return None

    def _refuse(self, why):
        self.refused[why] += 1
        return why


class TimestampStore:
    """The outgoing timestamp across restarts: it never goes backwards (the spec asks it to be
    saved and restored, since the clock may be behind after a restart).
    """

    def __init__(self, path):
        self.path = path

    def start(self, now=None):
        """The first outgoing timestamp: past the one saved last, and not behind the clock."""
        saved = 0
        try:
            with open(self.path) as fh:
                saved = int(fh.read().strip() or 0)
        except (OSError, ValueError):
            pass
        return max(saved + 1, now_timestamp(now))

    def save(self, timestamp):
        _write_private(self.path, '%d\n' % timestamp)


class StreamStore:
    """The incoming streams' last accepted timestamps across restarts: one line per stream,
    ``system component link timestamp``, written whole and renamed into place (mode 600).
    Saved once a second by the bridge and at its stop: a frame accepted in the second before a
    crash is the only one that could be played again after the restart.
    """

    def __init__(self, path):
        self.path = path

    def load(self):
        """{(system, component, link): timestamp}; lines that cannot be read are skipped."""
        streams = {}
        try:
            with open(self.path) as fh:
                lines = fh.read().splitlines()
        except OSError:
            return streams
        for line in lines:
            parts = line.split()
            if len(parts) == 4 and all(p.isdigit() for p in parts):
                system, component, link, timestamp = map(int, parts)
                streams[(system, component, link)] = timestamp
        return dict(list(streams.items())[-MAX_STREAMS:])

    def save(self, streams):
        _write_private(self.path, ''.join('%d %d %d %d\n' % (*k, t)
                                          for k, t in list(streams.items())))


def _write_private(path, text):
    tmp = path + '.tmp'
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, 'w') as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
