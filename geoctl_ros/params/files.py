"""ROS 2 parameter files: reading them as ROS does, and what each node takes from them."""
import yaml

from geoctl_ros.params.param import CONTROLLER, ConfigError
from geoctl_ros.params.schema import BY_NAME, CONE_KEY, schema_for


def flatten(tree: dict, prefix: str = '') -> dict:
    """Nested dicts -> one dict with dotted keys, as ROS 2 reads parameter files."""
    out = {}
    for key, value in tree.items():
        name = '%s.%s' % (prefix, key) if prefix else str(key)
        if isinstance(value, dict):
            out.update(flatten(value, name))
        else:
            out[name] = value
    return out


def write_parameter_file(sections: dict, path: str, comment: str) -> None:
    """Write sections ({node or '/**': flat parameters}) as a ROS 2 parameter file (nested keys,
    floats exact) under a first line of comment.
    """
    doc = {}
    for node, flat in sections.items():
        tree: dict = {}
        for key, value in flat.items():
            *parents, leaf = key.split('.')
            d = tree
            for p in parents:
                d = d.setdefault(p, {})
            d[leaf] = value.tolist() if hasattr(value, 'tolist') else value
        doc[node] = {'ros__parameters': tree}
    with open(path, 'w') as f:
        f.write('# %s\n' % comment)
        yaml.safe_dump(doc, f, sort_keys=False, default_flow_style=None, width=100)


def load_parameter_file(path: str) -> dict:
    """Read a ROS 2 parameter YAML file: {node name or '/**': flat parameter dict}."""
    try:
        with open(path) as f:
            doc = yaml.safe_load(f) or {}
    except OSError as e:
        raise ConfigError([(str(path), 'cannot be read (%s)' % (e.strerror or e))]) from None
    except yaml.YAMLError as e:
        mark, context = getattr(e, 'problem_mark', None), getattr(e, 'context_mark', None)
        where = ' at line %d, column %d' % (mark.line + 1, mark.column + 1) if mark else ''
        if context is not None and getattr(e, 'context', None):
            where += ' (%s at line %d)' % (e.context, context.line + 1)
        what = getattr(e, 'problem', None) or str(e).splitlines()[0]
        raise ConfigError([(str(path), 'not valid YAML%s: %s' % (where, what))]) from None
    if not isinstance(doc, dict):
        raise ConfigError([(str(path),
                            'not a ROS 2 parameter file (top level must be a mapping)')])
    sections = {}
    for node, body in doc.items():
        if not isinstance(body, dict) or not isinstance(body.get('ros__parameters'), dict):
            raise ConfigError([(str(node), 'section needs a ros__parameters mapping')])
        sections[str(node)] = flatten(body['ros__parameters'])
    return sections


def node_overrides(sections: dict, node: str) -> dict:
    """The flat overrides node gets from a parameter file: the sections that address it ('/**',
    its own, '/' + its own) in the file's order, a later one's value over an earlier one's, as
    rclpy applies them (so '/**' after the node's own section wins over it).

    Parameters in '/**' that node does not read are dropped (ROS ignores them too); its own section
    must contain only its parameters.
    """
    own = {p.name for p in schema_for(node)}
    merged: dict = {}
    for key, values in sections.items():
        if key == '/**':
            merged.update({k: v for k, v in values.items()
                           if k in own or (node == CONTROLLER and CONE_KEY.match(k))
                           or k not in BY_NAME and not CONE_KEY.match(k)})
        elif key in (node, '/' + node):
            merged.update(values)
    return merged


