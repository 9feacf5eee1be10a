"""The controller node's ride-through of input gaps without ROS: a pose gap flown on the gyro, an
imu gap on rates from successive poses, both, the limits, and what is counted.
"""

from loop_support import SPIN, feed, fly_spinning, make_loop, spinning
import numpy as np
import pytest

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.supervisor import gaps
from geoctl_ros.core.telemetry.diagnostics import ERROR, WARN

pytestmark = pytest.mark.odroid


def test_a_pose_gap_is_flown_on_the_attitude_propagated_with_the_gyro():
    loop = make_loop()
    tick = fly_spinning(loop, 0.6, pose_until=0.2)             # poses stop: a 0.4 s gap
    assert tick.armed and tick.bridging
    # constant rate: gyro propagation from the last pose is exact
    R_true = spinning(0.6)
    assert np.allclose(loop.bridge.R, R_true, atol=1e-12)
    # the control step (cone margins included) ran on the propagated attitude
    cones = loop.setup.config.cones
    assert np.allclose(tick.control.margins_deg, cones.margins_deg(R_true), atol=1e-9)
    st = loop.status(0.6)
    assert st.level == WARN
    assert 'pose gap: attitude propagated with the gyro (pose 0.400 s old, failsafe at 0.500 s)' \
        in st.message


def test_a_pose_gap_longer_than_the_limit_fails_safe_at_the_limit():
    loop = make_loop()
    fly_spinning(loop, 0.69, pose_until=0.2)                   # 0.49 s: still flying
    assert loop.supervisor.armed
    tick = loop.tick(0.705, 0.01)                              # 0.505 s: past the limit
    assert not tick.armed and not tick.motors.commands.any()
    assert loop.supervisor.reason == ('failsafe: pose lost (last 0.505 s ago, ride-through '
                                      'limit 0.500 s)')
    assert loop.status(0.705).level == ERROR


def test_an_imu_gap_is_flown_on_rates_from_successive_poses():
    loop = make_loop()
    dbar = []
    tick = fly_spinning(loop, 0.3, imu_until=0.1)              # gyro stops: a 0.2 s gap
    assert tick.armed and tick.bridging
    # constant rate: the rate from two poses 50 ms apart is exact
    assert np.allclose(loop.bridge.Omega, SPIN, atol=1e-9)
    assert np.allclose(tick.control.e_Omega, SPIN, atol=1e-9)      # R_d still: e_Omega = Omega
    assert 'angular velocity gap: rate from successive poses (imu 0.200 s old, failsafe at ' \
        '0.250 s)' in loop.status(0.3).message
    # the estimate does not learn from a bridged state
    dbar.append(loop.controller.delta_bar.copy())
    loop.offer_pose(so3.rot_to_quat(spinning(0.305)), 0.305, 0.305)
    loop.tick(0.31, 0.01)
    assert np.array_equal(loop.controller.delta_bar, dbar[0])
    # past the limit: failsafe
    tick = loop.tick(0.36, 0.01)
    assert not tick.armed
    assert loop.supervisor.reason.startswith('failsafe: angular velocity lost (last 0.260 s')


def test_both_gaps_hold_the_rate_and_propagate_until_the_shorter_limit():
    loop = make_loop()
    tick = fly_spinning(loop, 0.34, pose_until=0.2, imu_until=0.2)   # both stop: 0.14 s gap
    assert tick.armed and tick.bridging
    assert loop.bridge.rate_source is gaps.HELD
    assert np.allclose(loop.bridge.R, spinning(0.34), atol=1e-12)    # held constant rate: exact
    assert not loop.tick(0.45, 0.01).armed                           # imu lost at 0.25 s
    # and the gyro reading it held was the last measurement
    assert np.allclose(loop.bridge.Omega, SPIN)


def test_arming_needs_fresh_inputs_even_within_the_ride_through():
    loop = make_loop()
    feed(loop, 0.0)
    loop.tick(0.0, 0.01)
    assert loop.offer_angular_velocity((0.0, 0.0, 0.0), 0.2, 0.2) is None   # pose 0.2 s old
    refused = loop.arm(0.2)
    assert not refused.ok and 'pose stale (last 0.200 s ago' in refused.message


def test_a_gap_and_its_length_are_counted_when_it_ends():
    loop = make_loop()
    fly_spinning(loop, 0.45, pose_until=0.2)
    loop.offer_pose(so3.rot_to_quat(spinning(0.45)), 0.45, 0.45)
    tick = loop.tick(0.45, 0.01)
    assert not tick.bridging
    gaps = loop.status(0.45).figures.pose_gaps
    assert gaps.ridden == 1 and gaps.longest == pytest.approx(0.25)
