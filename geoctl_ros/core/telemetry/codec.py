"""The one diagnostics codec: typed figures to a DiagnosticStatus's key/values and back.

Each node declares its figures as a dataclass and a table of its keys (field -> ``Key``); a
``Codec`` of the two formats the figures for publishing (``to_values``) and reads a status back as
typed figures (``from_values``), for every reader (the MAVLink bridge, the recorder's report, the
tools, the tests). The controller's table is ``core/telemetry/diagnostics.py``'s, the MAVLink
bridge's ``mavlink/health.py``'s and the ESC node's ``esc/health.py``'s: renaming a key changes one
line of one table. ROS-free: the nodes turn the pairs into KeyValue messages and back.
"""
from dataclasses import Field, fields
from typing import (
    Any,
    Callable,
    ClassVar,
    Dict,
    Generic,
    Iterable,
    List,
    NamedTuple,
    Optional,
    Protocol,
    Tuple,
    Type,
    TypeVar,
)


class Dataclass(Protocol):
    """A dataclass's instance (typeshed's ``_typeshed.DataclassInstance``, which is no module
    to import at run time).
    """

    __dataclass_fields__: ClassVar[Dict[str, 'Field[object]']]


# the figures' dataclass of one codec
FiguresT = TypeVar('FiguresT', bound=Dataclass)


class Key(NamedTuple):
    """How one field of the figures is published.

    (text and parse take and give the field's value, of its own type in each table entry: Any,
    as a table of mixed fields cannot say more; omit takes the figures.)
    """

    key: str                                # the key; for an expanded field, its keys' prefix
    text: Callable[[Any], str] = str        # value -> text
    parse: Callable[[str], Any] = str       # text -> value (ValueError: left at its default)
    omit: Optional[Callable[[Any], bool]] = None   # figures -> leave the key out
    expand: bool = False                    # a mapping: one key per entry, prefix + its name
    entries: Optional[Tuple[str, ...]] = None      # an expanded field's names, when its
                                            # prefix alone cannot tell its keys from others'
    numbered: bool = False                  # an expanded tuple: entries named 1, 2, ...


class Codec(Generic[FiguresT]):
    """Figures of one dataclass to key/value pairs and back."""

    def __init__(self, cls: Type[FiguresT], table: Dict[str, Key], required: Tuple[str, ...] = ()):
        """table: field -> Key, in the order published; required: the fields a status must
        carry to be one of these (``from_values`` gives None otherwise).
        """
        assert set(table) <= {f.name for f in fields(cls)}, set(table)
        self.cls, self.table, self.required = cls, table, required
        self._by_key = {k.key: name for name, k in table.items() if not k.expand}
        self._expanded = [(name, k) for name, k in table.items() if k.expand]

    def key(self, name: str) -> str:
        """The published key of a field (for a reader that wants the text itself)."""
        return self.table[name].key

    def to_values(self, figures: FiguresT) -> List[Tuple[str, str]]:
        """The figures as (key, text) pairs, in the table's order."""
        pairs = []
        for name, k in self.table.items():
            if k.omit is not None and k.omit(figures):
                continue
            value = getattr(figures, name)
            if k.expand:
                items = (((str(i), v) for i, v in enumerate(value, 1)) if k.numbered
                         else value.items())
                pairs += [(k.key + entry, k.text(v)) for entry, v in items]
            else:
                pairs.append((k.key, k.text(value)))
        return pairs

    def from_values(self, pairs: Iterable[Tuple[str, str]]
                    ) -> Tuple[Optional[FiguresT], Dict[str, str]]:
        """(figures, the pairs that are not theirs) from a status's pairs; (None, all of them)
        when a required key is missing. Keys this version does not know are returned, and a
        value that does not parse is left at its default: a reader never fails on a report.
        """
        found: Dict[str, Any] = {}
        expanded: Dict[str, Dict[str, Any]] = {name: {} for name, _ in self._expanded}
        rest = {}
        for key, text in pairs:
            name = self._by_key.get(key)
            try:
                if name is not None:
                    found[name] = self.table[name].parse(text)
                    continue
                for field_name, k in self._expanded:
                    entry = key[len(k.key):]
                    if key.startswith(k.key) and (k.entries is None or entry in k.entries) and (
                            not k.numbered or entry.isdigit()):
                        expanded[field_name][entry] = k.parse(text)
                        break
                else:
                    rest[key] = text
            except (ValueError, AttributeError, IndexError):
                continue
        if any(name not in found for name in self.required):
            return None, rest
        for name, k in self._expanded:
            entries = expanded[name]
            found[name] = (tuple(entries[e] for e in sorted(entries, key=int)) if k.numbered
                           else entries)
        return self.cls(**found), rest
