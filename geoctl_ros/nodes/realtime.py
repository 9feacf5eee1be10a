"""The flight chain's real-time class: ``realtime PRIORITY COMMAND [ARGS...]`` runs COMMAND in
SCHED_FIFO at PRIORITY (1-99; 0: at normal priority), as ``chrt -f PRIORITY COMMAND`` would.
It is testbed.launch.xml's launch prefix for the controller, ``esc_i2c`` and ``mavlink_bridge``,
and serves any other node the same way (``ros2 run --prefix``).

Where the class is not permitted (no ``rtprio`` in /etc/security/limits.conf and no
CAP_SYS_NICE: a development machine, a test), it says so in one line on stderr and runs COMMAND
at normal priority, where ``chrt`` would stop. It tells COMMAND the priority it asked for (the
environment variable ``core.telemetry.scheduling.ASKED``): a node of this package then says at
WARN that it runs outside the class, and shows its class under the diagnostics key
``scheduling``. The threads COMMAND creates inherit the class (Fast DDS's included).
``ps -o pid,cls,rtprio,comm -C controller`` shows it too: ``FF`` and the priority in the
real-time class, ``TS`` and ``-`` outside it.

Exit code: COMMAND's (it replaces this process); 2 for bad arguments, 127 when COMMAND cannot
be run.
"""
import os
import sys
from typing import List, Optional

from geoctl_ros.core.telemetry.scheduling import ALLOW, ASKED

USAGE = 'usage: realtime PRIORITY COMMAND [ARGS...]   (PRIORITY 1-99 for SCHED_FIFO, 0: normal)'


def enter_realtime(priority: int) -> Optional[str]:
    """Put this process in SCHED_FIFO at priority; None when done, else why not (the system's
    words).
    """
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as e:
        return e.strerror or str(e)
    return None


WRAPPERS = {'nice', 'taskset', 'chrt', 'ionice', 'env', 'setpriv', 'stdbuf', 'numactl'}


def command_name(command: List[str]) -> str:
    """The name of the program a command runs, past its wrappers (``nice -n 3 .../controller
    --ros-args ...``: controller): the first path to a file that is not a wrapper, else the
    command's first word.
    """
    for word in command:
        if os.sep in word and os.path.isfile(word) and os.path.basename(word) not in WRAPPERS:
            return os.path.basename(word)
    return os.path.basename(command[0])


def main(argv: Optional[List[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) < 2 or not argv[0].isdigit() or not 0 <= int(argv[0]) <= 99:
        sys.stderr.write(USAGE + '\n')
        return 2
    priority, command = int(argv[0]), argv[1:]
    name = command_name(command)
    if priority:
        why = enter_realtime(priority)
        if why is None:
            sys.stderr.write('realtime: %s in the real-time class (SCHED_FIFO %d)\n'
                             % (name, priority))
        else:
            sys.stderr.write('realtime: SCHED_FIFO %d is not permitted here (%s): %s runs at '
                             'normal priority (to allow it: %s)\n' % (priority, why, name, ALLOW))
        os.environ[ASKED] = str(priority)
    else:
        os.environ.pop(ASKED, None)
    sys.stderr.flush()
    try:
        os.execvp(command[0], command)
    except OSError as e:
        sys.stderr.write('realtime: cannot run %s: %s\n' % (command[0], e.strerror or e))
        return 127
    return 0       # (not reached: execvp replaced this process)


if __name__ == '__main__':
    sys.exit(main())
