"""The package's layers: the folders and core's rooms import only downwards, nothing imports
itself round a circle, the ROS-free layers import without rclpy, and nothing outside params/
reads a parameter by its name (each checked on every module, parsed).
"""
import ast
import pathlib
import re
import subprocess
import sys

import pytest
from source_support import PKG, ROOT, imported_modules

from geoctl_ros.params.schema import SCHEMA

pytestmark = pytest.mark.odroid

LAYERS = ['core', 'params', 'sim', 'plots', 'records', 'esc', 'mavlink', 'campaign', 'falsify',
          'benchmark', 'nodes', 'sil', 'fuzz', 'cli']    # lowest first
# core's rooms, lowest first: the geometry, the paper's law, actuation, the sensors, telemetry, and
# the supervisor (the node's logic without ROS), which uses them all
CORE_ROOMS = ['geometry', 'law', 'actuation', 'sensors', 'telemetry', 'supervisor']


def test_core_sim_params_and_mavlink_import_without_rclpy():
    """With rclpy (and every ROS message package) made unimportable."""
    code = ('import sys\n'
            'class Block:\n'
            '    def find_spec(self, name, path=None, target=None):\n'
            '        if name.split(".")[0] in ("rclpy", "rcl_interfaces", "std_msgs", '
            '"geometry_msgs", "sensor_msgs", "diagnostic_msgs", "builtin_interfaces"):\n'
            '            raise ImportError("blocked: " + name)\n'
            'sys.meta_path.insert(0, Block())\n'
            'import pkgutil, importlib, geoctl_ros\n'
            'import importlib.util\n'
            '# plots: where matplotlib is (the extra tools; not on the vehicle stack)\n'
            'for sub in ("core", "sim", "params", "mavlink", "records", "esc") + (\n'
            '        ("plots",) if importlib.util.find_spec("matplotlib") else ()):\n'
            '    pkg = importlib.import_module("geoctl_ros." + sub)\n'
            '    for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):\n'
            '        importlib.import_module(m.name)\n'
            'import geoctl_ros.sil.rosenv\n'
            'print("ok")\n')
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0 and r.stdout.strip() == 'ok', r.stderr


def test_no_layer_imports_a_higher_one():
    """The package's folders (LAYERS) and core's rooms (CORE_ROOMS): each module imports only
    from its own or a lower one (TYPE_CHECKING imports too).
    """
    rank = {name: i for i, name in enumerate(LAYERS)}
    room_rank = {name: i for i, name in enumerate(CORE_ROOMS)}
    bad = []
    for path in sorted(pathlib.Path(PKG).rglob('*.py')):
        parts = path.relative_to(PKG).parts
        if len(parts) < 2:
            continue
        layer = parts[0]
        for mod in imported_modules(str(path)):
            m = re.match(r'geoctl_ros\.(\w+)(?:\.(\w+))?', mod)
            if not m or m.group(1) not in rank:
                continue
            if rank[m.group(1)] > rank[layer]:
                bad.append('%s imports %s' % ('/'.join(parts), mod))
            elif layer == m.group(1) == 'core' and len(parts) > 2:
                if m.group(2) not in room_rank:
                    bad.append('%s imports %s: not a room of core' % ('/'.join(parts), mod))
                elif room_rank[m.group(2)] > room_rank[parts[1]]:
                    bad.append('%s imports %s' % ('/'.join(parts), mod))
    assert not bad, bad
    assert sorted(p.name for p in pathlib.Path(PKG, 'core').iterdir()
                  if p.suffix == '.py' and p.name != '__init__.py') == [], (
        'core/ holds its rooms only')


def test_the_esc_layer_does_not_import_the_controllers_supervisor():
    """esc/ (the ESC node's driver, health and buses) may import core, but not core.supervisor,
    the controller's decisions: what the two exchange (the armed state, the ESCs' health, the
    motor_commands check) is core.actuation.esc_wire's, which both import.
    """
    def supervisor_imports(source):
        for node in ast.walk(ast.parse(source)):
            names = []
            if isinstance(node, ast.ImportFrom) and node.module:
                # (the names too: `from geoctl_ros.core import supervisor`)
                names = [node.module] + ['%s.%s' % (node.module, a.name) for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            yield from (n for n in names if re.match(r'geoctl_ros\.core\.supervisor(\.|$)', n))

    assert list(supervisor_imports('from geoctl_ros.core import supervisor\n'))   # it sees one
    bad = ['esc/%s imports %s' % (path.name, mod)
           for path in sorted(pathlib.Path(PKG, 'esc').rglob('*.py'))
           for mod in supervisor_imports(path.read_text())]
    assert not bad, bad


def _supervisor_loaded_by(modules):
    """The core.supervisor modules that importing these modules loads, in a fresh interpreter
    (what they import, and what that imports, down to the package __init__ files).
    """
    code = ('import importlib, sys\n'
            'for m in %r:\n'
            '    importlib.import_module(m)\n'
            'print(" ".join(k for k in sorted(sys.modules)\n'
            '               if k.startswith("geoctl_ros.core.supervisor")))\n' % (modules,))
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    return r.stdout.split()


def test_the_esc_node_does_not_load_the_controllers_supervisor():
    """Nor through anything it imports: esc/'s modules and the ESC node (nodes/esc_i2c.py), the
    parameters they read (params/ takes build.py, which brings in the supervisor, on first use).
    """
    esc = sorted('geoctl_ros.esc.' + p.stem for p in pathlib.Path(PKG, 'esc').glob('*.py')
                 if p.stem != '__init__')
    assert len(esc) >= 5
    # it sees one: a module that imports params' builders
    assert 'geoctl_ros.core.supervisor.safety' in _supervisor_loaded_by(
        esc + ['geoctl_ros.params.build'])
    assert _supervisor_loaded_by(esc + ['geoctl_ros.nodes.esc_i2c']) == []


def _module_graph():
    """{module: modules of this package and of benchmarks/ it imports} over every file, with the
    imports under TYPE_CHECKING and inside functions (a name imported from a package that is a
    module of it counts as that module).
    """
    files = {}
    for path in pathlib.Path(PKG).rglob('*.py'):
        rel = path.relative_to(ROOT).with_suffix('')
        name = '.'.join(rel.parts[:-1] if rel.name == '__init__' else rel.parts)
        files[name] = path
    for path in pathlib.Path(ROOT, 'benchmarks').glob('*.py'):
        files[path.stem] = path
    graph = {}
    for name, path in files.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                for a in node.names:
                    sub = '%s.%s' % (node.module, a.name)
                    deps.add(sub if sub in files else node.module)
            elif isinstance(node, ast.Import):
                deps.update(a.name for a in node.names)
        graph[name] = {d for d in deps if d in files and d != name}
    return graph


def test_no_module_imports_itself_round_a_circle():
    """No cycle in the import graph of the package and benchmarks/, TYPE_CHECKING imports and
    imports inside functions included (a package's __init__ importing its own modules aside).
    """
    graph = _module_graph()
    for name, deps in graph.items():      # (an __init__ re-exporting its modules is not a circle)
        graph[name] = {d for d in deps if not d.startswith(name + '.')}
    state, cycles = {}, []

    def visit(node, stack):
        state[node] = 1
        stack.append(node)
        for dep in sorted(graph[node]):
            if state.get(dep) == 1:
                cycles.append(' -> '.join(stack[stack.index(dep):] + [dep]))
            elif dep not in state:
                visit(dep, stack)
        stack.pop()
        state[node] = 2
    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    assert not cycles, cycles
    # and it sees one: a planted circle is found
    graph['geoctl_ros.core.geometry.so3'] = {'geoctl_ros.core.law.control'}
    state.clear()
    visit('geoctl_ros.core.law.control', [])
    assert cycles


def _parameter_read(node, names):
    """The parameter a syntax node reads by its name (a subscript, or .get/.pop/.setdefault/
    .get_parameter, with a literal, a '%' format or an f-string that starts with one), or None.
    """
    def literal(x):
        if isinstance(x, ast.Constant) and isinstance(x.value, str):
            return x.value
        if isinstance(x, ast.BinOp) and isinstance(x.op, ast.Mod):
            return literal(x.left)
        if isinstance(x, ast.JoinedStr) and x.values:
            return literal(x.values[0])
        return None
    if isinstance(node, ast.Subscript) and isinstance(node.ctx, ast.Load):
        key = literal(node.slice)
    elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.args
          and node.func.attr in ('get', 'pop', 'setdefault', 'get_parameter')):
        key = literal(node.args[0])
    else:
        return None
    return key if key is not None and (key in names or key.startswith('cones.')) else None


def test_no_module_outside_params_reads_a_parameter_by_its_name():
    """params/ turns parameters into typed set-ups (ControllerSetup, TestbedSetup, ScenarioOptions,
    EscSetup, GainSet, ...); every other module of the package and of benchmarks/ reads those, not
    the parameter dicts. Checked on the syntax tree of every module; writing a parameter (a
    scenario file's sections, an override) is not a read. The check finds a planted read.
    """
    names = {p.name for p in SCHEMA}
    planted = ast.parse("x = values['k_R'] + v.get('pose_timeout') + v['cones.%s.axis' % n]\n"
                        "values['k_R'] = 1.0\n")
    assert sorted(k for n in ast.walk(planted) if (k := _parameter_read(n, names))) == [
        'cones.%s.axis', 'k_R', 'pose_timeout']
    reads = []
    for path in sorted(list(pathlib.Path(PKG).rglob('*.py'))
                       + list(pathlib.Path(ROOT, 'benchmarks').rglob('*.py'))):
        if pathlib.Path(PKG, 'params') in path.parents:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            key = _parameter_read(node, names)
            if key:
                reads.append('%s:%d %s' % (path.relative_to(ROOT), node.lineno, key))
    assert not reads, reads
