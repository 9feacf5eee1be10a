"""A process's scheduling class as the flight chain's nodes report it: in the real-time class
(SCHED_FIFO or SCHED_RR, at a priority) or at normal priority, and whether the ``realtime`` launch
prefix (``geoctl_ros.nodes.realtime``) asked for the class. Each node of the flight chain
(controller, ``esc_i2c``, ``mavlink_bridge``) shows it under the diagnostics key ``scheduling``,
and says at start-up, at WARN, when the class was asked for and not given.

ROS-free: the operating system's own figures (``os.sched_getscheduler``), read once at start-up.
"""
import os
import re
from typing import Mapping, NamedTuple, Optional

ASKED = 'GEOCTL_REALTIME_PRIORITY'    # set by the realtime prefix: the priority it asked for
REALTIME_POLICIES = ('SCHED_FIFO', 'SCHED_RR')
ALLOW = "'<user> - rtprio 98' in /etc/security/limits.conf, then log in again"


class Scheduling(NamedTuple):
    """A process's scheduling: its policy's name (SCHED_FIFO, SCHED_OTHER, ...), its real-time
    priority (0 outside the real-time class), and the priority the realtime prefix asked for (0:
    none asked).
    """

    policy: str = 'SCHED_OTHER'
    priority: int = 0
    asked: int = 0

    @property
    def realtime(self) -> bool:
        return self.policy in REALTIME_POLICIES


_POLICIES = {getattr(os, name): name for name in
             ('SCHED_OTHER', 'SCHED_BATCH', 'SCHED_IDLE', 'SCHED_FIFO', 'SCHED_RR')
             if hasattr(os, name)}


def scheduling(environ: Optional[Mapping[str, str]] = None) -> Scheduling:
    """This process's Scheduling (environ: where the prefix's ASKED is read; os.environ)."""
    environ = os.environ if environ is None else environ
    try:
        policy = _POLICIES.get(os.sched_getscheduler(0), 'SCHED_OTHER')
        priority = os.sched_getparam(0).sched_priority
    except (OSError, AttributeError):          # (a system without these calls: not real-time)
        policy, priority = 'SCHED_OTHER', 0
    asked = environ.get(ASKED, '')
    return Scheduling(policy, priority, int(asked) if asked.isdigit() else 0)


def scheduling_text(s: Scheduling) -> str:
    """The diagnostics value: ``SCHED_FIFO 50``; ``normal priority (SCHED_OTHER): SCHED_FIFO 50
    not permitted``; ``normal priority (SCHED_OTHER)``.
    """
    if s.realtime:
        return '%s %d' % (s.policy, s.priority)
    text = 'normal priority (%s)' % s.policy
    return text + (': SCHED_FIFO %d not permitted' % s.asked if s.asked else '')


_TEXT = re.compile(r'(SCHED_FIFO|SCHED_RR) (\d+)$|normal priority \((\w+)\)'
                   r'(?:: SCHED_FIFO (\d+) not permitted)?$')


def scheduling_value(text: str) -> Scheduling:
    """A Scheduling from its diagnostics value (ValueError for another text)."""
    m = _TEXT.match(text)
    if m is None:
        raise ValueError(text)
    if m.group(1):
        return Scheduling(m.group(1), int(m.group(2)), 0)
    return Scheduling(m.group(3), 0, int(m.group(4) or 0))


def scheduling_problem(s: Scheduling) -> Optional[str]:
    """The WARN line of a node that the realtime prefix could not put in the real-time class,
    else None.
    """
    if not s.asked or s.realtime:
        return None
    return ('not in the real-time class: SCHED_FIFO %d is not permitted to this user, so this '
            'node runs at normal priority and any busy process can delay it (to allow it: %s)'
            % (s.asked, ALLOW))
