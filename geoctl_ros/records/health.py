"""The recorder's diagnostics as typed values and their keys (a table of the one codec,
``core.telemetry.codec``): messages written and dropped so far.
"""
from dataclasses import dataclass
from typing import List, Tuple

from geoctl_ros.core.telemetry.codec import Codec, Key

NAME = 'geoctl_ros: record'


@dataclass(frozen=True)
class RecordFigures:
    """What the recorder reports besides level and message."""

    messages: int = 0          # written to the bag so far
    dropped: int = 0           # lost because the writer could not keep up


CODEC = Codec(RecordFigures, {
    'messages': Key('messages', parse=int),
    'dropped': Key('dropped', parse=int),
})


def to_values(figures: RecordFigures) -> List[Tuple[str, str]]:
    """The diagnostics key/value pairs of the recorder's figures."""
    return CODEC.to_values(figures)
