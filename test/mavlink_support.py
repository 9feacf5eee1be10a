"""What the MAVLink bridge's tests over UDP share (test_mavlink_bridge and its _signed twin):
a pymavlink endpoint on 127.0.0.1, the arm command, the lab's signing key.
"""
import hashlib
import os
import socket
import time

os.environ['MAVLINK20'] = '1'
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mav

from geoctl_ros.sil.rosenv import config_dir

TESTBED = os.path.join(config_dir(), 'testbed.yaml')
SYSID = 7


# A stall of the controller's loop that the vehicle would feel: a period as long as the pose
# timeout (config/testbed.yaml: 0.1 s). Shorter ones come from the shared machine, not the link:
# on a busy CI machine the loop period's max reached 60 ms in this test with nothing wrong.
STALL_MS = 100.0


def loop_period_max_ms(diagnostic):
    """The largest loop period of the controller's last diagnostics window, ms."""
    return 1e3 * diagnostic.figures.loop_period.max


def free_udp_port():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(('127.0.0.1', 0))
    port = s.getsockname()[1]
    s.close()
    return port


class Endpoint:
    """A pymavlink endpoint on 127.0.0.1 that keeps what it receives. Every one opened is closed
    by the rig, a failed test's too (one left open is a socket this process still holds).
    """

    opened = []

    def __init__(self, url, sysid, compid):
        self.conn = mavutil.mavlink_connection(url, source_system=sysid, source_component=compid,
                                               dialect='common')
        self.got = []
        Endpoint.opened.append(self)

    @classmethod
    def close_all(cls):
        while cls.opened:
            cls.opened.pop().conn.close()

    def poll(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            m = self.conn.recv_match(blocking=True, timeout=0.02)
            if m is not None and m.get_type() != 'BAD_DATA':
                self.got.append((time.monotonic(), m))

    def wait(self, pred, timeout, what, mon=None, since=None):
        """The first message received at or after since (default: now) that pred accepts."""
        since = time.monotonic() if since is None else since
        end = time.monotonic() + timeout
        while True:
            for t, m in self.got:
                if t >= since and pred(m):
                    return m
            if time.monotonic() > end:
                raise TimeoutError('timed out waiting for ' + what)
            self.poll(0.05)
            if mon is not None:
                mon.spin_for(0.01)

    def since(self, t0, kind):
        return [m for t, m in self.got if t >= t0 and m.get_type() == kind]



def arm(gcs, mon):
    """Send MAV_CMD_COMPONENT_ARM_DISARM (arm) as a ground station; the final COMMAND_ACK
    result.
    """
    t0 = time.monotonic()
    gcs.conn.mav.command_long_send(SYSID, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0,
                                   0, 0)
    return gcs.wait(lambda m: m.get_type() == 'COMMAND_ACK' and
                    m.result != mav.MAV_RESULT_IN_PROGRESS, 10.0, 'the arm answer', mon,
                    since=t0).result


def statustext(gcs, prefix, timeout, mon, since):
    """The first whole STATUSTEXT received since since that starts with prefix: its chunks (one
    id, in chunk_seq order; the last one shorter than 50 characters) joined.
    """
    def whole():
        chunks = {}
        for m in gcs.since(since, 'STATUSTEXT'):
            if not m.id:
                if m.text.startswith(prefix):
                    return m.text
                continue
            chunks.setdefault(m.id, {})[m.chunk_seq] = m.text
        for parts in chunks.values():
            text = ''.join(parts[k] for k in sorted(parts))
            if (text.startswith(prefix) and sorted(parts) == list(range(len(parts)))
                    and len(parts[len(parts) - 1]) < 50):
                return text
        return None
    gcs.wait(lambda m: whole() is not None, timeout, 'a STATUSTEXT: ' + prefix, mon, since)
    return whole()


def is_ours(m):
    return m.get_srcSystem() == SYSID and m.get_srcComponent() == mav.MAV_COMP_ID_AUTOPILOT1



PASSPHRASE = 'lab passphrase'
KEY = hashlib.sha256(PASSPHRASE.encode()).digest()          # as ground stations derive it


def key_file(tmp_path, mode=0o600):
    f = tmp_path / 'mavlink.key'
    f.write_text(PASSPHRASE + '\n')
    f.chmod(mode)
    return str(f)


def _as_sent(value):
    """A value as a ROS parameter can carry it: a list mixing ints and floats as floats."""
    if isinstance(value, list) and any(isinstance(v, float) for v in value):
        return [float(v) for v in value]
    return value
