"""One pymavlink connection, read and written on a thread of its own.

The ROS executor never touches the socket: it queues messages to send (``send``) and takes what
arrived (``receive``). A slow, dead or flooding link therefore never delays the node. Both queues
are bounded: when full, the oldest incoming message is dropped and counted, and outgoing messages
are dropped and counted, so memory stays bounded too.

Connection strings are pymavlink's (``udpout:127.0.0.1:14550``, ``udpin:0.0.0.0:14550``,
``tcp:host:port``, ``/dev/ttyUSB0,921600``). MAVLink 2 (``MAVLINK20=1`` is set before pymavlink
is imported) and the common dialect, chosen explicitly.
"""
import os
import queue
import threading
import time

os.environ['MAVLINK20'] = '1'
from pymavlink import mavutil  # noqa: E402  (after MAVLINK20)

DIALECT = 'common'


def encoder(system_id, component_id):
    """A MAVLink 2 message encoder of the common dialect (no I/O), for building messages."""
    mav = mavutil.mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
    mav.WIRE_PROTOCOL_VERSION = '2.0'
    return mav


class Link:
    """A MAVLink connection served by a thread; counters for the diagnostics."""

    def __init__(self, url, system_id, component_id, capacity=1000):
        self.url = url
        self.conn = mavutil.mavlink_connection(url, source_system=system_id,
                                               source_component=component_id, dialect=DIALECT,
                                               robust_parsing=True, autoreconnect=True)
        self._in = queue.Queue(maxsize=capacity)
        self._out = queue.Queue(maxsize=capacity)
        self.counts = {'received': 0, 'bad data': 0, 'dropped in': 0, 'sent': 0,
                       'dropped out': 0, 'send errors': 0}
        self.last_error = ''
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name='mavlink ' + url, daemon=True)
        self._thread.start()

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
                    conn.mav.send(msg)
                    self.counts['sent'] += 1
                except Exception as e:        # a dead link must not kill the thread
                    self.counts['send errors'] += 1
                    self.last_error = str(e)
            try:
                msg = conn.recv_match(blocking=True, timeout=0.01)
            except Exception as e:            # garbage the parser cannot take, a closed port
                self.counts['bad data'] += 1
                self.last_error = str(e)
                time.sleep(0.01)
                continue
            if msg is None:
                continue
            if msg.get_type() == 'BAD_DATA' or msg.get_type().startswith('UNKNOWN'):
                self.counts['bad data'] += 1
                continue
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
