"""The flight chain's launch prefix ``realtime PRIORITY COMMAND`` (docs/interface.md,
"Scheduling"): the command in SCHED_FIFO at that priority where the class is permitted; where it
is not (the capability dropped and RLIMIT_RTPRIO 0, as for a user without an rtprio line), one
line says so and the command runs at normal priority; 0 leaves the class alone. The command
learns what was asked: a node's ``scheduling`` diagnostics key and its start-up WARN
(core.telemetry.scheduling) say so, in the three nodes' codecs alike.
"""
import ctypes
import os
import resource
import subprocess
import sys

import pytest

from geoctl_ros.core.telemetry import diagnostics
from geoctl_ros.core.telemetry.scheduling import (
    Scheduling,
    scheduling,
    scheduling_problem,
    scheduling_text,
)
from geoctl_ros.esc import health as esc_health
from geoctl_ros.mavlink import health as bridge_health

pytestmark = pytest.mark.odroid

# the command run under the prefix: its own scheduling class and priority, as it sees them
SHOW = ('import os; print(os.sched_getscheduler(0) == os.SCHED_FIFO, '
        'os.sched_getparam(0).sched_priority)')
# ... and as a node of the package reports them (its diagnostics value; its WARN line)
REPORT = ('from geoctl_ros.core.telemetry.scheduling import *; s = scheduling(); '
          'print(scheduling_text(s)); print(scheduling_problem(s))')
PR_CAPBSET_DROP, CAP_SYS_NICE = 24, 23


def realtime(*args, permitted=True):
    def not_permitted():
        resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
        # root (as here) may use the class whatever the limit: drop the capability for the
        # command (a user without it cannot drop it, and has no use of the class without rtprio)
        ctypes.CDLL(None, use_errno=True).prctl(PR_CAPBSET_DROP, CAP_SYS_NICE, 0, 0, 0)
    return subprocess.run([sys.executable, '-m', 'geoctl_ros.nodes.realtime'] + list(args),
                          capture_output=True, text=True, timeout=60,
                          preexec_fn=None if permitted else not_permitted)


def test_where_the_class_is_not_permitted_one_line_says_so_and_the_command_runs_normally():
    r = realtime('50', sys.executable, '-c', SHOW, permitted=False)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ['False', '0']
    assert r.stderr.splitlines() == [
        "realtime: SCHED_FIFO 50 is not permitted here (Operation not permitted): %s runs at "
        "normal priority (to allow it: '<user> - rtprio 98' in /etc/security/limits.conf, then "
        'log in again)' % os.path.basename(sys.executable)]


def test_where_it_is_permitted_the_command_runs_in_the_class_at_that_priority():
    try:                            # (in a child: this process keeps its own class)
        pid = os.fork()
        if pid == 0:
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
                os._exit(0)
            except OSError:
                os._exit(1)
        allowed = os.waitpid(pid, 0)[1] == 0
    except OSError:
        allowed = False
    if not allowed:
        pytest.skip('the real-time class is not permitted to this user here')
    r = realtime('3', sys.executable, '-c', SHOW)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ['True', '3']
    assert r.stderr.splitlines() == ['realtime: %s in the real-time class (SCHED_FIFO 3)'
                                     % os.path.basename(sys.executable)]


def test_priority_0_leaves_the_class_alone_and_bad_arguments_are_refused():
    r = realtime('0', sys.executable, '-c', SHOW)
    assert (r.returncode, r.stdout.split(), r.stderr) == (0, ['False', '0'], '')
    for args in (['x', 'true'], ['100', 'true'], ['50']):
        r = realtime(*args)
        assert r.returncode == 2 and r.stderr.startswith('usage: realtime PRIORITY'), args
    r = realtime('0', '/nonexistent/controller')
    assert r.returncode == 127 and 'cannot run /nonexistent/controller' in r.stderr


def test_a_node_under_the_prefix_reports_its_class_and_warns_when_it_was_refused():
    r = realtime('50', sys.executable, '-c', REPORT, permitted=False)
    assert r.returncode == 0, r.stderr
    text, problem = r.stdout.splitlines()
    assert text == 'normal priority (SCHED_OTHER): SCHED_FIFO 50 not permitted'
    assert problem == (
        'not in the real-time class: SCHED_FIFO 50 is not permitted to this user, so this node '
        'runs at normal priority and any busy process can delay it (to allow it: '
        "'<user> - rtprio 98' in /etc/security/limits.conf, then log in again)")
    # not asked (no prefix, or priority 0): normal priority, and nothing to warn about
    r = realtime('0', sys.executable, '-c', REPORT)
    assert r.stdout.splitlines() == ['normal priority (SCHED_OTHER)', 'None']
    assert scheduling({}).asked == 0 and scheduling({'GEOCTL_REALTIME_PRIORITY': 'x'}).asked == 0
    assert scheduling({'GEOCTL_REALTIME_PRIORITY': '40'}).asked == 40
    assert scheduling_problem(Scheduling('SCHED_FIFO', 40, 40)) is None


@pytest.mark.parametrize('s', [Scheduling('SCHED_FIFO', 50, 0), Scheduling('SCHED_RR', 1, 0),
                               Scheduling('SCHED_OTHER', 0, 50), Scheduling('SCHED_OTHER', 0, 0)])
def test_the_three_nodes_publish_the_class_under_one_key_and_read_it_back(s):
    figures = (diagnostics.Figures(scheduling=s), esc_health.EscFigures(scheduling=s),
               bridge_health.BridgeStatus('udpout:127.0.0.1:14550', None, scheduling=s))
    for f, codec in zip(figures, (diagnostics.CODEC, esc_health.CODEC, bridge_health.CODEC)):
        pairs = codec.to_values(f)
        assert ('scheduling', scheduling_text(s)) in pairs
        assert codec.from_values(pairs)[0].scheduling == s
    # a report without it (the loop's own, before the node adds it) leaves the key out
    assert 'scheduling' not in dict(diagnostics.to_values(diagnostics.Figures()))
