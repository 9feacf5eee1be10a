"""The MAVLink bridge's own health as typed values, and the one place that spells its diagnostics
keys (a table of the one codec, ``core.telemetry.codec``): ``to_values`` formats a ``BridgeStatus``
for a DiagnosticStatus, ``from_values`` reads one back (as the tests and tools do).

Counters keep the names their owners give them (``Link.counts``: received, bad data, ...;
``Verifier.refused``: unsigned, bad signature, ...; the bridge's own: arm requests, ...).
"""
from dataclasses import dataclass, field
from typing import Dict, List, NamedTuple, Optional, Tuple

from geoctl_ros.core.telemetry.codec import Codec, Key
from geoctl_ros.core.telemetry.scheduling import Scheduling, scheduling_text, scheduling_value

NAME = 'geoctl_ros: mavlink_bridge'

BRIDGE_COUNTS = IGNORED, ARM_REQUESTS, PARAM_SETS, STATUSTEXT, REFUSED_INPUT, HANDLER_ERRORS = (
    'ignored', 'arm requests', 'param sets', 'statustext',      # the bridge's own counters
    'inputs refused', 'handler errors')

NO_GCS_HEARTBEAT = 'no ground station heartbeat'
NO_AUTOPILOT_HEARTBEAT = 'no autopilot heartbeat'


@dataclass(frozen=True)
class BridgeStatus:
    """What the bridge reports about its link; ages in s (None: never heard)."""

    url: str
    gcs_age: Optional[float]
    link_counts: Dict[str, int] = field(default_factory=dict)
    counts: Dict[str, int] = field(default_factory=dict)
    signing_link_id: Optional[int] = None          # None: unsigned
    refused: Dict[str, int] = field(default_factory=dict)
    last_refused: str = ''
    last_error: str = ''
    autopilot_age: Optional[float] = None
    autopilot_messages: Optional[int] = None        # None: no autopilot link configured
    scheduling: Optional[Scheduling] = None         # the node's class

    @property
    def signing(self):
        return self.signing_link_id is not None


def _age_text(age):
    return 'none yet' if age is None else 'heartbeat %.1f s ago' % age


def _age(text):
    if text.startswith('heartbeat '):
        return float(text.split()[1])
    return None


def _signing_text(link_id):
    return 'off' if link_id is None else 'on (link id %d)' % link_id


def _signing(text):
    if text == 'off':
        return None
    if not text.startswith('on (link id '):
        raise ValueError(text)
    return int(text[len('on (link id '):].rstrip(')'))


def _unsigned(s):
    return s.signing_link_id is None


# The bridge's keys, in the order published (the one codec: ``core.telemetry.codec``).
CODEC = Codec(BridgeStatus, {
    'url': Key('link'),
    'gcs_age': Key('ground station', _age_text, _age),
    'link_counts': Key('link ', parse=int, expand=True),
    'counts': Key('', parse=int, expand=True, entries=BRIDGE_COUNTS),
    'signing_link_id': Key('signing', _signing_text, _signing),
    'refused': Key('refused ', parse=int, omit=_unsigned, expand=True),
    'last_refused': Key('last refused', omit=lambda s: _unsigned(s) or not s.last_refused),
    'last_error': Key('link last error', lambda e: e[:80], omit=lambda s: not s.last_error),
    'autopilot_age': Key('autopilot', _age_text, _age,
                         omit=lambda s: s.autopilot_messages is None),
    'autopilot_messages': Key('autopilot imu messages', parse=int,
                              omit=lambda s: s.autopilot_messages is None),
    'scheduling': Key('scheduling', scheduling_text, scheduling_value,
                      omit=lambda s: s.scheduling is None),
}, required=('url', 'gcs_age'))


def to_values(s: BridgeStatus) -> List[Tuple[str, str]]:
    """The diagnostics key/value pairs of a BridgeStatus."""
    return CODEC.to_values(s)


def from_values(pairs) -> Tuple[Optional[BridgeStatus], Dict[str, str]]:
    """(BridgeStatus, the other key/values) from a status's key/value pairs; (None, ...) when
    they are not the bridge's. Unparsable values are left at their defaults, never raised.
    """
    return CODEC.from_values(pairs)


class Report(NamedTuple):
    """One diagnostics status of the bridge, read back: level (0 OK, 1 WARN), message, figures."""

    level: int
    message: str
    status: BridgeStatus
