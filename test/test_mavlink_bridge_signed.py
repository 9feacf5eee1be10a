"""The MAVLink bridge with a signing key (only the station holding it reads, sets, arms and
disarms), and a ground station's motor test through the ESC node (mavlink_support.py: the
endpoint and helpers).
"""
import hashlib
import os
import socket
import time

import pytest
import rclpy

os.environ['MAVLINK20'] = '1'
from mavlink_support import KEY, SYSID, TESTBED, Endpoint, free_udp_port, is_ours, key_file
from pymavlink.dialects.v20 import common as mav
from support import FakeInputs

from geoctl_ros.esc.virtual import VirtualEscBus
from geoctl_ros.mavlink.params import TABLE
from geoctl_ros.sil.processes import NodeProcess

pytestmark = pytest.mark.dds


def test_a_key_file_others_can_read_stops_the_bridge(tmp_path):
    p = NodeProcess('mavlink_bridge', None, ('-p', 'mavlink.signing_key_file:=%s'
                                             % key_file(tmp_path, 0o644)), log_dir=tmp_path)
    try:
        assert p.proc.wait(30) == 2
        assert 'readable or writable by group or others' in p.output()
    finally:
        p.stop()


@pytest.mark.realtime
def test_with_a_key_only_the_station_holding_it_reads_sets_arms_and_disarms(tmp_path):
    gcs_port = free_udp_port()
    gcs = Endpoint('udpin:127.0.0.1:%d' % gcs_port, 255, 190)
    gcs.conn.setup_signing(KEY, sign_outgoing=True)         # it also refuses unsigned frames
    procs = [NodeProcess('sim', TESTBED, log_dir=tmp_path),
             NodeProcess('controller', TESTBED, log_dir=tmp_path),
             NodeProcess('mavlink_bridge', None, (
                 '-p', 'mavlink.url:=udpout:127.0.0.1:%d' % gcs_port,
                 '-p', 'mavlink.system_id:=%d' % SYSID,
                 '-p', 'mavlink.signing_key_file:=%s' % key_file(tmp_path)), log_dir=tmp_path)]
    rclpy.init()
    mon = FakeInputs()
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        g = gcs.conn.mav
        gcs.wait(lambda m: m.get_type() == 'HEARTBEAT' and is_ours(m), 40.0, 'a signed heartbeat')
        bridge = next(iter(gcs.conn.clients))               # the bridge's address
        g.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        # (the arm below needs the controller's sensor checks to have a window to judge)
        mon.wait_for(mon.controller_can_judge_its_sensors, 30.0,
                     'the controller to receive the sim')
        t0 = time.monotonic()
        g.param_request_list_send(SYSID, 1)
        gcs.wait(lambda m: m.get_type() == 'PARAM_VALUE' and m.param_index == len(TABLE) - 1,
                 5.0, 'the whole parameter list')
        assert len({p.param_id for p in gcs.since(t0, 'PARAM_VALUE')}) == len(TABLE)
        t0 = time.monotonic()
        g.param_set_send(SYSID, 1, b'GC_K_R', 0.5, mav.MAV_PARAM_TYPE_REAL32)
        p = gcs.wait(lambda m: m.get_type() == 'PARAM_VALUE' and m.param_id == 'GC_K_R', 5.0,
                     'the new k_R', mon, since=t0)
        assert p.param_value == pytest.approx(0.5)
        captured = g.command_long_encode(SYSID, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0,
                                         0, 0, 0, 0).pack(g)      # an arm, as a sniffer sees it
        t0 = time.monotonic()
        gcs.conn.write(captured)
        assert gcs.wait(lambda m: m.get_type() == 'COMMAND_ACK' and
                        m.result != mav.MAV_RESULT_IN_PROGRESS, 10.0, 'the arm answer', mon,
                        since=t0).result == mav.MAV_RESULT_ACCEPTED
        mon.wait_for(lambda: mon.last_diagnostic().figures.armed, 3.0, 'armed')
        t0 = time.monotonic()
        g.command_long_send(SYSID, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 0, 0, 0, 0, 0, 0)
        mon.wait_for(lambda: mon.last_diagnostic().figures.armed is False, 5.0, 'disarmed')
        # what a stranger on the link tries, from its own address: each must leave it disarmed
        unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        guess = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        guess.signing.secret_key = hashlib.sha256(b'guess').digest()
        guess.signing.sign_outgoing, guess.signing.link_id = True, g.signing.link_id
        guess.signing.timestamp = g.signing.timestamp + 1                     # a wrong key
        wrong_key = guess.command_long_encode(SYSID, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1,
                                              0, 0, 0, 0, 0, 0).pack(guess)
        guess.signing.timestamp = g.signing.timestamp + 24 * 3600 * 100_000   # a day ahead
        for frame in (unsigned.command_long_encode(SYSID, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM,
                                                   0, 1, 0, 0, 0, 0, 0, 0).pack(unsigned),
                      wrong_key,
                      unsigned.param_set_encode(SYSID, 1, b'GC_K_R', 0.9,
                                                mav.MAV_PARAM_TYPE_REAL32).pack(unsigned),
                      captured,                                          # the replay
                      guess.command_long_encode(SYSID, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM,
                                                0, 1, 0, 0, 0, 0, 0, 0).pack(guess)):
            stranger.sendto(frame, bridge)
        t_sent = time.monotonic()

        def refusals():
            reports = mon.since('bridge', t_sent)
            return reports and {k: reports[-1].status.refused[k]
                                for k in ('unsigned', 'replayed', 'bad signature')}
        mon.wait_for(lambda: refusals() == {'unsigned': 2, 'replayed': 1, 'bad signature': 2},
                     5.0,
                     "the stranger's five frames refused (2 unsigned, 1 replay, 2 bad signatures)")
        assert mon.last_diagnostic().figures.armed is False
        # the genuine station is not locked out by the forged frame from the future
        t0 = time.monotonic()
        g.param_request_read_send(SYSID, 1, b'GC_K_R', -1)
        p = gcs.wait(lambda m: m.get_type() == 'PARAM_VALUE', 5.0, 'a parameter read', mon,
                     since=t0)
        assert p.param_value == pytest.approx(0.5)                    # the stranger's 0.9 not
        bridge_status = mon.last('bridge').status
        assert bridge_status.signing and bridge_status.signing_link_id == 0
        assert 'from' in bridge_status.last_refused
    finally:
        stranger.close()
        mon.destroy_node()
        rclpy.try_shutdown()
        for p in procs:
            p.stop()
        gcs.conn.close()



def test_a_ground_stations_motor_test_spins_one_motor_through_the_esc_node(tmp_path):
    """MAV_CMD_DO_MOTOR_TEST from a ground station, through the bridge, to esc_i2c, on a virtual
    ESC bus that this process powers (no controller: disarmed): rotor 3 gets 12 % for 1 s, as the
    bus itself recorded, and the others zero; out of range it is denied with the ESC node's reason.
    """
    path = str(tmp_path / 'esc_bus')
    addresses = (0x29, 0x2A, 0x2B, 0x2C, 0x2D, 0x2E)
    escs = VirtualEscBus(path, addresses)
    escs.power(True)
    gcs_port = free_udp_port()
    gcs = Endpoint('udpin:127.0.0.1:%d' % gcs_port, 255, 190)
    procs = [NodeProcess('esc_i2c', TESTBED, ('-p', 'esc.virtual_bus:=' + path), log_dir=tmp_path),
             NodeProcess('mavlink_bridge', None, (
                 '-p', 'mavlink.url:=udpout:127.0.0.1:%d' % gcs_port,
                 '-p', 'mavlink.system_id:=%d' % SYSID), log_dir=tmp_path)]
    try:
        gcs.wait(lambda m: m.get_type() == 'HEARTBEAT' and is_ours(m), 30.0, 'the bridge')

        def motor_test(rotor, percent, seconds):
            t0 = time.monotonic()
            for _ in range(60):             # until the ESC node's services are up
                gcs.conn.mav.command_long_send(SYSID, 1, mav.MAV_CMD_DO_MOTOR_TEST, 0, rotor,
                                               mav.MOTOR_TEST_THROTTLE_PERCENT, percent,
                                               seconds, 0, 0, 0)
                ack = gcs.wait(lambda m: m.get_type() == 'COMMAND_ACK' and
                               m.result != mav.MAV_RESULT_IN_PROGRESS, 10.0, 'the answer',
                               since=t0)
                if ack.result != mav.MAV_RESULT_TEMPORARILY_REJECTED:
                    return ack.result, t0
                t0 = time.monotonic()
                gcs.poll(0.5)
            return ack.result, t0
        result, t0 = motor_test(3, 12.0, 1.0)
        assert result == mav.MAV_RESULT_ACCEPTED
        gcs.wait(lambda m: m.get_type() == 'STATUSTEXT' and 'rotor 3 at 0.12' in m.text, 5.0,
                 'the ESC node saying so', since=t0)
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:  # the test ends by itself: zero again
            log = escs.log()
            spun = log[(log['address'] == 0x2B) & (log['b0'] > 0)]
            if len(spun) and log['b0'][log['address'] == 0x2B][-1] == 0:
                break
            time.sleep(0.1)
        assert set(spun['b0']) == {round(0.12 * 240)}                      # 29 of 240
        # the 1 s test, as the bus saw it: its first write may come late on a busy machine (this
        # is not a real-time test), its last within a write cycle of the end
        assert 0.5 < spun['t'][-1] - spun['t'][0] < 1.2
        others = log[log['address'] != 0x2B]
        assert len(others) and not others['b0'].any()
        n = escs.count()
        result, t0 = motor_test(3, 50.0, 1.0)                              # beyond 0.3
        assert result == mav.MAV_RESULT_DENIED
        gcs.poll(0.5)
        said = ''.join(m.text for m in gcs.since(t0, 'STATUSTEXT'))      # (in 50-char chunks)
        assert 'motor_test.command: must be in [0, 0.3]' in said, said
        assert not escs.log(n)['b0'].any()
    finally:
        for p in procs:
            p.stop()
        escs.close()
        Endpoint.close_all()
