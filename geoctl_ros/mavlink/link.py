"""One pymavlink connection, read and written on a thread of its own.

The ROS executor never touches the socket: it queues messages to send (``send``) and takes what
arrived (``receive``). A slow, dead or flooding link therefore never delays the node. Both queues
are bounded: when full, the oldest incoming message is dropped and counted, and outgoing messages
are dropped and counted, so memory stays bounded too.

Connection strings are pymavlink's (``udpout:127.0.0.1:14550``, ``udpin:0.0.0.0:14550``,
``tcp:host:port``, ``/dev/ttyUSB0,921600``). MAVLink 2 (``MAVLINK20=1`` is set before pymavlink
is imported) and the common dialect, chosen explicitly.

Bad input is counted and passed over. On UDP each datagram holds whole packets, so each datagram
is parsed from a clean parser: garbage cannot leave a bogus header behind that swallows the next
datagram's packet as its payload (pymavlink's parser keeps its buffer across datagrams; with 50
datagrams of random bytes before each command, 11 of 20 commands went unanswered that way).

With a signing key (``signing=``) every outgoing message is signed and every incoming one but
``signing.UNSIGNED_ALLOWED`` must be signed with the key and newer than the last of its stream
(``geoctl_ros.mavlink.signing.Verifier``); refusals are counted and the latest kept, with the
sender's address, in ``refusals``.
"""
import collections
import os
import queue
import socket
import threading
import time

os.environ['MAVLINK20'] = '1'
from pymavlink import mavutil  # noqa: E402  (after MAVLINK20)

from geoctl_ros.mavlink.signing import UNSIGNED_ALLOWED, Verifier, now_timestamp  # noqa: E402

DIALECT = 'common'
DATAGRAMS_PER_READ = 2000
UDP_MAX = 65535
RECEIVE_BUFFER = 4 << 20          # bytes asked of the kernel (it caps them at net.core.rmem_max)


def encoder(system_id, component_id):
    """A MAVLink 2 message encoder of the common dialect (no I/O), for building messages."""
    mav = mavutil.mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
    mav.WIRE_PROTOCOL_VERSION = '2.0'
    return mav


def parse_datagram(mav, data):
    """(messages, whether something in it was not a whole packet) of one datagram, parsed by
    the MAVLink object mav from a clean state. Garbage the parser raises on is bad data too: the
    datagram's other packets are lost with it, never the link.
    """
    mav.buf, mav.buf_index, mav.have_prefix_error = bytearray(), 0, False   # clean
    mav.expected_length = mavutil.mavlink.HEADER_LEN_V1 + 2
    try:
        got = mav.parse_buffer(data) or []
    except Exception:          # pymavlink's MAVError and what its decoders raise on garbage
        return [], True
    return got, mav.buf_len() > 0        # a packet cut short, or a header and no packet


class Link:
    """A MAVLink connection served by a thread; counters for the diagnostics."""

    def __init__(self, url, system_id, component_id, capacity=1000, signing=None):
        """signing: None, or (key, link id, first outgoing timestamp, the incoming streams' last
        timestamps of the previous run): then every frame is checked and signed from the first on.
        """
        self.url = url
        self.conn = mavutil.mavlink_connection(url, source_system=system_id,
                                               source_component=component_id, dialect=DIALECT,
                                               robust_parsing=True, autoreconnect=True)
        self._datagrams = isinstance(self.conn, mavutil.mavudp)
        self.conn.first_byte = False        # no switch to MAVLink 1 on a first v1 frame
        self._in = queue.Queue(maxsize=capacity)
        self._out = queue.Queue(maxsize=capacity)
        self.counts = {'received': 0, 'bad data': 0, 'dropped in': 0, 'sent': 0,
                       'dropped out': 0, 'send errors': 0, 'datagrams': 0, 'refused': 0}
        if self._datagrams:                  # room for a burst while the thread is not running
            try:
                self.conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
            except OSError:
                pass
        self.last_error = ''
        self.verifier = None                 # with a key: what checks incoming frames
        self._tx = None                      # with a key: the signing encoder of what goes out
        self.refusals = collections.deque(maxlen=20)   # (why, message type, sender address)
        self._sender = None                  # the address of the datagram being parsed
        if signing is not None:
            self._use_signing(*signing)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name='mavlink ' + url, daemon=True)
        self._thread.start()

    def _use_signing(self, key, link_id, first_timestamp, streams=None):
        """Sign what goes out and check what comes in with key (32 bytes)."""
        tx = mavutil.mavlink.MAVLink(None, srcSystem=self.conn.mav.srcSystem,
                                     srcComponent=self.conn.mav.srcComponent)
        tx.signing.secret_key, tx.signing.sign_outgoing = key, True
        tx.signing.link_id, tx.signing.timestamp = link_id, first_timestamp
        self.verifier, self._tx = Verifier(key, streams=streams), tx

    @property
    def signing_timestamp(self):
        """The next outgoing signing timestamp (None without a key)."""
        return None if self._tx is None else self._tx.signing.timestamp

    def send(self, msg):
        """Queue a message (from pymavlink's *_encode) for sending."""
        try:
            self._out.put_nowait(msg)
        except queue.Full:
            self.counts['dropped out'] += 1

    def receive(self, limit=200):
        """The messages that arrived since the last call (at most limit)."""
        out = []
        while len(out) < limit:
            try:
                out.append(self._in.get_nowait())
            except queue.Empty:
                break
        return out

    def _run(self):
        conn = self.conn
        while not self._stop.is_set():
            while True:
                try:
                    msg = self._out.get_nowait()
                except queue.Empty:
                    break
                try:
                    if self._tx is None:
                        conn.mav.send(msg)
                    else:                     # signed; the timestamp keeps up with the clock
                        sig = self._tx.signing
                        sig.timestamp = max(sig.timestamp, now_timestamp())
                        conn.write(msg.pack(self._tx))
                    self.counts['sent'] += 1
                except Exception as e:        # a dead link must not kill the thread
                    self.counts['send errors'] += 1
                    self.last_error = str(e)
            try:
                msgs = self._read(conn)
            except Exception as e:            # garbage the parser cannot take, a closed port
                self.counts['bad data'] += 1
                self.last_error = str(e)
                time.sleep(0.01)
                continue
            for msg in msgs:
                self._take(msg)

    def _read(self, conn):
        """The messages that arrived within 10 ms: every waiting datagram's (up to
        DATAGRAMS_PER_READ), or the next of a stream; without those refused for their signature.
        """
        if not self._datagrams:
            msg = conn.recv_match(blocking=True, timeout=0.01)
            self._sender = self.url
            return [] if msg is None or not self._signed_or_allowed(msg) else [msg]
        if not conn.select(0.01):
            return []
        mav, msgs = conn.mav, []
        for _ in range(DATAGRAMS_PER_READ):
            try:
                data, self._sender = conn.port.recvfrom(UDP_MAX)
            except (BlockingIOError, ConnectionRefusedError):
                break
            self.counts['datagrams'] += 1
            got, bad = parse_datagram(mav, data)
            if bad:
                self.counts['bad data'] += 1
            taken = [m for m in got if self._signed_or_allowed(m)]
            for msg in taken:
                conn.post_message(msg)
            msgs += taken
            if any(m.get_type() != 'BAD_DATA' for m in taken):
                # a peer to answer (what mavudp.recv does for every datagram: here only for
                # one that held a message this link takes, so garbage and refused senders get
                # no telemetry)
                if conn.udp_server:
                    conn.clients.add(self._sender)
                    conn.clients_last_alive[self._sender] = time.time()
                elif conn.broadcast:
                    conn.last_address = self._sender
        return msgs

    def _signed_or_allowed(self, msg):
        kind = msg.get_type()
        if self.verifier is None or kind in UNSIGNED_ALLOWED or kind == 'BAD_DATA':
            return True
        why = self.verifier.check(msg.get_msgbuf())
        if why is None:
            return True
        self.counts['refused'] += 1
        self.refusals.append((why, kind, self._sender))
        return False

    def _take(self, msg):
        if msg.get_type() == 'BAD_DATA' or msg.get_type().startswith('UNKNOWN'):
            self.counts['bad data'] += 1
            return
        self.counts['received'] += 1
        if self._in.full():
            try:
                self._in.get_nowait()
            except queue.Empty:
                pass
            self.counts['dropped in'] += 1
        self._in.put_nowait(msg)

    def close(self):
        self._stop.set()
        self._thread.join(2.0)
        try:
            self.conn.close()
        except Exception:
            pass
