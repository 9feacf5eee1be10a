"""The MAVLink bridge's own health as typed values, and the one place that spells its diagnostics
keys: ``to_values`` formats a ``BridgeStatus`` for a DiagnosticStatus, ``from_values`` reads one
back (as the tests and tools do). The controller's keys are ``core/diagnostics.py``'s.

Counters keep the names their owners give them (``Link.counts``: received, bad data, ...;
``Verifier.refused``: unsigned, bad signature, ...; the bridge's own: arm requests, ...).
"""
from dataclasses import dataclass, field
from typing import Dict, NamedTuple, Optional, Tuple

NAME = 'geoctl_ros: mavlink_bridge'

_LINK = 'link'
_GCS = 'ground station'
_SIGNING = 'signing'
_LAST_REFUSED = 'last refused'
_LAST_ERROR = 'link last error'
_AUTOPILOT = 'autopilot'
_AUTOPILOT_IMU = 'autopilot imu messages'
_LINK_COUNT = 'link '          # + a Link counter's name
_REFUSED = 'refused '          # + a Verifier refusal's name
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

    @property
    def signing(self):
        return self.signing_link_id is not None


def _age_text(age):
    return 'none yet' if age is None else 'heartbeat %.1f s ago' % age


def _age(text):
    if text.startswith('heartbeat '):
        return float(text.split()[1])
    return None


def to_values(s):
    """The diagnostics key/values (str -> str) of a BridgeStatus."""
    values = {_LINK: s.url, _GCS: _age_text(s.gcs_age)}
    values.update({_LINK_COUNT + k: str(n) for k, n in s.link_counts.items()})
    values.update({k: str(n) for k, n in s.counts.items()})
    if s.signing_link_id is None:
        values[_SIGNING] = 'off'
    else:
        values[_SIGNING] = 'on (link id %d)' % s.signing_link_id
        values.update({_REFUSED + k: str(n) for k, n in s.refused.items()})
        if s.last_refused:
            values[_LAST_REFUSED] = s.last_refused
    if s.last_error:
        values[_LAST_ERROR] = s.last_error[:80]
    if s.autopilot_messages is not None:
        values[_AUTOPILOT] = _age_text(s.autopilot_age)
        values[_AUTOPILOT_IMU] = str(s.autopilot_messages)
    return values


def from_values(pairs) -> Tuple[Optional[BridgeStatus], Dict[str, str]]:
    """(BridgeStatus, the other key/values) from a status's key/value pairs; (None, ...) when
    they are not the bridge's. Unparsable numbers are skipped, never raised.
    """
    values = dict(pairs)
    if _LINK not in values or _GCS not in values:
        return None, values
    link_counts, counts, refused = {}, {}, {}
    signing_link_id = None
    rest = {}
    for k, v in values.items():
        try:
            if k in (_LINK, _GCS, _LAST_REFUSED, _LAST_ERROR, _AUTOPILOT, _AUTOPILOT_IMU):
                continue
            if k == _SIGNING:
                if v.startswith('on (link id '):
                    signing_link_id = int(v[len('on (link id '):].rstrip(')'))
            elif k.startswith(_LINK_COUNT):
                link_counts[k[len(_LINK_COUNT):]] = int(v)
            elif k.startswith(_REFUSED):
                refused[k[len(_REFUSED):]] = int(v)
            elif k in BRIDGE_COUNTS:
                counts[k] = int(v)
            else:
                rest[k] = v
        except ValueError:
            continue
    autopilot = values.get(_AUTOPILOT_IMU)
    return BridgeStatus(
        url=values[_LINK], gcs_age=_age(values[_GCS]), link_counts=link_counts, counts=counts,
        signing_link_id=signing_link_id, refused=refused,
        last_refused=values.get(_LAST_REFUSED, ''), last_error=values.get(_LAST_ERROR, ''),
        autopilot_age=_age(values.get(_AUTOPILOT, '')),
        autopilot_messages=int(autopilot) if autopilot and autopilot.isdigit() else None), rest


class Report(NamedTuple):
    """One diagnostics status of the bridge, read back: level (0 OK, 1 WARN), message, figures."""

    level: int
    message: str
    status: BridgeStatus
