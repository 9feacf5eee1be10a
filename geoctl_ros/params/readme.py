"""The parameter table, generated from the schema.

./run shell -m geoctl_ros.params.readme --write-readme docs/parameters.md
"""
import os
import sys

import numpy as np

from geoctl_ros.params.files import load_parameter_file, node_overrides
from geoctl_ros.params.param import CONTROLLER
from geoctl_ros.params.schema import CHANGE_WHILE_ARMED, CONE_SCHEMA, SCHEMA

TESTBED = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(
    __file__)))), 'config', 'testbed.yaml')


def testbed_values(path: str = TESTBED) -> dict:
    """What config/testbed.yaml sets for each parameter (the node's section it reaches)."""
    sections = load_parameter_file(path)
    out: dict = {}
    for node in ('scenario', 'sim', CONTROLLER):        # (the controller's wins a shared name)
        out.update(node_overrides(sections, node))
    return out


def markdown_table() -> str:
    """The parameter table: the schema's default, and config/testbed.yaml's value where it sets
    one that differs.
    """
    testbed = testbed_values() if os.path.exists(TESTBED) else {}
    rows = ['| parameter | node | type | default | config/testbed.yaml | range | unit | meaning |',
            '|---|---|---|---|---|---|---|---|']
    for p in SCHEMA + CONE_SCHEMA:
        default = '(required)' if p.default is None else _fmt_default(p.default)
        given = testbed.get(p.name)
        lab = ('' if given is None or (p.default is not None and np.array_equal(
            np.asarray(given, dtype=object), np.asarray(p.default, dtype=object)))
            else _fmt_default(given.tolist() if hasattr(given, 'tolist') else given))
        rows.append('| `%s` | %s | %s%s | %s | %s | %s | %s | %s%s |' % (
            p.name, ', '.join(p.nodes), p.type, '[%d]' % p.length if p.length else '', default,
            lab, p.range_text, p.unit, p.doc,
            '' if CONTROLLER not in p.nodes or p.name in CHANGE_WHILE_ARMED
            else ' (not while armed)'))
    return '\n'.join(rows)


def _fmt_default(value):
    if isinstance(value, bool):
        return '`%s`' % str(value).lower()
    if isinstance(value, str):
        return '`%s`' % value if value else '`""`'
    return '`%s`' % (value,)


README_MARKERS = ('<!-- params:begin -->', '<!-- params:end -->')


def update_readme(path: str) -> bool:
    """Replace the table between README_MARKERS in the file at path; True if it changed."""
    with open(path) as f:
        text = f.read()
    begin, end = README_MARKERS
    i, j = text.index(begin) + len(begin), text.index(end)
    new = text[:i] + '\n' + markdown_table() + '\n' + text[j:]
    if new != text:
        with open(path, 'w') as f:
            f.write(new)
    return new != text


if __name__ == '__main__':
    if sys.argv[1:2] == ['--write-readme']:
        print('updated' if update_readme(sys.argv[2]) else 'up to date')
    else:
        sys.stdout.write(markdown_table() + '\n')

