"""The diagnostics contracts (the controller's, geoctl_ros.core.telemetry.diagnostics; the MAVLink
bridge's, geoctl_ros.mavlink.health): what is reported comes back typed from what is published, a
reader survives any text, and no other file spells a key.
"""
import dataclasses
import math
import os
import pathlib

import numpy as np
import pytest

from geoctl_ros.core.telemetry import diagnostics
from geoctl_ros.core.telemetry.diagnostics import (
    Counts,
    Figures,
    Gaps,
    Window,
    from_values,
    key,
    to_values,
)
from geoctl_ros.core.telemetry.stats import WindowStats
from geoctl_ros.esc import health as esc_health
from geoctl_ros.mavlink import health

pytestmark = pytest.mark.odroid
ROOT = pathlib.Path(__file__).resolve().parent.parent


def test_published_figures_read_back_as_they_were_to_the_printed_precision():
    ages = WindowStats()
    for x in np.linspace(0.001, 0.012, 50):
        ages.add(x)
    f = Figures(armed=True, state='armed', pose_age=0.0123, imu_age=0.0042,
                pose_counts=Counts(1200, 3), imu_counts=Counts(2400, 0),
                pose_age_at_tick=ages.window(), imu_age_at_tick=None,
                pose_gaps=Gaps(2, 0.25), imu_gaps=Gaps(0, 0.0), ticks_bridging=4, ticks=50,
                psi=0.00384, min_cone_margin_deg=14.73, motor_commands=(120, 0, 33, 240, 7, 9),
                loop_period=Window(0.01, 0.0004, 0.0112, 0.0131))
    pairs = to_values(f)
    assert (key('armed'), 'True') in pairs and (key('pose_counts'), '1200/3') in pairs
    back = from_values(pairs)
    assert back.armed and back.state == 'armed' and back.pose_counts == (1200, 3)
    assert back.pose_gaps == (2, 0.25) and back.ticks == 50 and back.imu_age_at_tick is None
    assert back.motor_commands == (120, 0, 33, 240, 7, 9)
    assert back.psi == pytest.approx(0.00384) and back.min_cone_margin_deg == pytest.approx(14.73)
    assert np.allclose(back.pose_age_at_tick, ages.window(), atol=1e-6)   # 1 us in ms text
    assert np.allclose(back.loop_period, f.loop_period, atol=1e-6)
    assert back.pose_age == pytest.approx(0.0123, abs=1e-4)


def test_before_the_first_step_the_step_figures_are_left_out_and_read_as_none():
    pairs = to_values(Figures(state='disarmed at start-up'))
    keys = [k for k, _ in pairs]
    assert key('psi') not in keys and key('motor_commands') not in keys
    back = from_values(pairs)
    assert back.psi is None and back.motor_commands is None and math.isinf(back.pose_age)
    assert not back.armed and not back.failsafe


def test_a_reader_never_fails_on_text_it_does_not_understand():
    back = from_values([(key('armed'), 'True'), (key('ticks'), 'many'),
                        (key('pose_counts'), '1/2/3'), (key('pose_age_at_tick'), 'mean x'),
                        ('a key of a later version', '1'),
                        (key('min_cone_margin_deg'), 'no cones'),
                        (key('pose_gaps'), 'several, long ones')])
    assert back.armed and back.ticks == 0 and back.pose_counts == (0, 0)
    assert back.pose_gaps == from_values([]).pose_gaps                # left at its default
    assert back.pose_age_at_tick is None and back.min_cone_margin_deg is None


BRIDGE = health.BridgeStatus(
    url='udpout:127.0.0.1:14550', gcs_age=1.25, link_counts={'received': 7, 'bad data': 13},
    counts=dict.fromkeys(health.BRIDGE_COUNTS, 2), signing_link_id=0,
    refused={'unsigned': 2, 'bad signature': 1, 'replayed': 0, 'too old': 0},
    last_refused='unsigned COMMAND_LONG from 127.0.0.1:5000', last_error='bad CRC',
    autopilot_age=None, autopilot_messages=17)


def test_the_bridge_status_reads_back_as_it_was():
    values = health.to_values(BRIDGE)
    back, rest = health.from_values(values + [('level', '1')])
    assert back == dataclasses.replace(BRIDGE, gcs_age=pytest.approx(1.2, abs=0.051))
    assert rest == {'level': '1'}
    unsigned, _ = health.from_values(health.to_values(health.BridgeStatus('udp', None)))
    assert not unsigned.signing and unsigned.gcs_age is None and unsigned.refused == {}
    assert unsigned.autopilot_messages is None                    # no autopilot link


def test_the_bridge_reader_never_fails_on_text_it_does_not_understand():
    values = dict(health.to_values(BRIDGE))
    for k, v in list(values.items()):          # garble the numbers 13 and 17, and the link id
        values[k] = {'13': 'lots', '17': '?', 'on (link id 0)': 'on (x)'}.get(v, v)
    back, _ = health.from_values(values.items())
    assert 'bad data' not in back.link_counts and back.link_counts['received'] == 7
    assert not back.signing and back.autopilot_messages is None
    assert health.from_values({'a key': 'of someone else'}.items())[0] is None


def test_no_other_file_spells_a_diagnostics_key():
    """Renaming a key changes one table of the one codec: core/telemetry/diagnostics.py (the
    controller's), mavlink/health.py (the bridge's) or esc/health.py (the ESC node's) only: no
    other source (package, tools, tests, benchmarks) writes a key of more than one word.
    """
    keys = [k.key for k in diagnostics.CODEC.table.values() if ' ' in k.key]
    assert len(keys) > 10
    bridge_keys = [k for k, _ in health.to_values(BRIDGE) if ' ' in k]
    assert len(bridge_keys) > 10
    keys += bridge_keys + [k.key for k in esc_health.CODEC.table.values() if ' ' in k.key]
    owners = {ROOT / 'geoctl_ros' / 'core' / 'telemetry' / 'diagnostics.py',
              ROOT / 'geoctl_ros' / 'mavlink' / 'health.py',
              ROOT / 'geoctl_ros' / 'esc' / 'health.py'}
    found = []
    for folder in ('geoctl_ros', 'test', 'benchmarks'):
        for path in (ROOT / folder).rglob('*.py'):
            if path in owners:
                continue
            text = path.read_text()
            found += ['%s: %r' % (os.path.relpath(path, ROOT), k) for k in keys
                      if "'%s'" % k in text or '"%s"' % k in text]
    assert not found, found
