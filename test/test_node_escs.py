"""The ESC node over real DDS, on the sim's virtual I2C bus: its start-up probe and what a silent
ESC does to the controller (node_support.py: the processes and the monitor node).
"""

from node_support import (
    TESTBED,
)
import pytest

from geoctl_ros.esc.virtual import VirtualEscBus
from geoctl_ros.params import (
    resolve,
)

pytestmark = pytest.mark.dds


def test_the_esc_node_refuses_to_start_without_its_escs_unless_told_to_ignore_one(ros, tmp_path):
    """No sim on the virtual bus: nobody answers, and esc_i2c stops naming the first address.
    With five ESCs powered and the sixth's rotor in esc.ignore it runs, and never writes it.
    """
    mon, launch = ros
    path = str(tmp_path / 'esc_bus')
    addresses = resolve('esc_i2c', {})['esc.addresses']
    bus = VirtualEscBus(path, addresses)
    try:
        alone = launch('esc_i2c', TESTBED, '-p', 'esc.virtual_bus:=' + path,
                       '-p', 'esc.probe_timeout:=0.0')
        assert alone.proc.wait(30) == 2
        assert 'the ESC of rotor 1 at 0x29 did not answer (I2C nack at 0x29)' in alone.output()
        bus.power(True)
        bus.slots['present'][5] = 0                                  # rotor 6 missing
        esc = launch('esc_i2c', TESTBED, '-p', 'esc.virtual_bus:=' + path,
                     '-p', 'esc.probe_timeout:=0.0', '-p', 'esc.ignore:=[6]')
        mon.wait_for(lambda: 'rotors [6] missing (ignored)' in esc.output(), 30.0, 'esc_i2c')

        def commanded():              # (published until the subscription is matched)
            mon.publish_commands([0.2] * 6, session=77)
            return bus.log()['b0'].max() > 0
        mon.act_as_controller(True, 77)   # this process plays an armed controller of session 77
        mon.wait_for(commanded, 10.0, 'a command at the ESCs')
        assert esc.stop() == 0
        log = bus.log()
        assert 0x2E not in set(log['address']) and len(set(log['address'])) == 5
        assert all(data == b'\x00' for data, _ in bus.setpoints()[:5])       # zero at the stop
    finally:
        bus.close()


def test_an_esc_that_stops_answering_fails_the_controller_safe_naming_it(ros, tmp_path):
    """The sim as the six ESCs on the virtual bus, esc_i2c and the controller: armed, rotor 4's ESC
    stops answering; esc_i2c's typed esc_health reaches the controller, which fails safe naming
    it, and refuses to arm again until it answers.
    """
    mon, launch = ros
    path = str(tmp_path / 'esc_bus')
    launch('sim', TESTBED, '-p', 'esc.virtual_bus:=' + path)
    esc = launch('esc_i2c', TESTBED, '-p', 'esc.virtual_bus:=' + path,
                 '-p', 'esc.probe_timeout:=20.0')
    launch('controller')
    mon.wait_for(lambda: '6 ESCs on virtual ESC bus' in esc.output(), 30.0, 'the ESC node')
    assert mon.arm_when_ready().success
    bus = VirtualEscBus(path, resolve('esc_i2c', {})['esc.addresses'])
    try:
        bus.slots['present'][3] = 0                              # rotor 4's ESC goes quiet
        # (on a starved machine an input may be lost first: then that failsafe comes first, and
        # the ESC is named beside it)
        mon.wait_for(lambda: not mon.last_diagnostic().figures.armed
                     and 'ESC of rotor 4 lost' in mon.last_diagnostic().message, 10.0,
                     'the failsafe')
        assert mon.last_diagnostic().figures.state.startswith('failsafe: ')
        refused = mon.arm(True)
        assert not refused.success and 'ESC of rotor 4 lost' in refused.message
        bus.slots['present'][3] = 1
        mon.wait_for(lambda: mon.arm(True).success, 10.0, 'arming once it answers again')
        assert mon.arm(False).success
    finally:
        bus.close()
