"""The package as a maintainer and a lab receive it: launch files that name only what exists, the
packaging metadata, colcon as on the vehicle, the numpy 1.26 and linter and mypy checks, the
scripts pip-installed, and the manual's links. (Its layers: test_layers.py.)

The launch files are checked here for what needs no launcher (they parse, and every executable,
parameter file and remapping they name exists); ``test_launch.py`` runs them with ``ros2 launch``.
"""
import ast
import functools
import importlib.util
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import numpy_api
import pytest
from source_support import PKG, ROOT, imported_modules, module_level_imports, package_modules
from workspace import Workspace

# on the vehicle's stack too, but for the development tools' pins (requirements.txt, the extra)
odroid = pytest.mark.odroid



def _console_scripts():
    text = open(os.path.join(ROOT, 'setup.py')).read()
    return set(re.findall(r"'(\w+) = geoctl_ros\.[\w.]+:\w+'", text))


@odroid
@pytest.mark.parametrize('name', ['testbed.launch.xml', 'sil.launch.xml'])
def test_launch_files_name_only_what_exists(name):
    root = ET.parse(os.path.join(ROOT, 'launch', name)).getroot()
    assert root.tag == 'launch'
    args = {a.get('name'): a.get('default') for a in root.iter('arg')}
    nodes = list(root.iter('node'))
    assert nodes
    subscribed = {'controller': {'pose', 'imu', 'attitude_setpoint'},
                  'sim': {'motor_commands', 'control_wrench'}, 'esc_i2c': {'motor_commands'}}
    for node in nodes:
        assert node.get('pkg') == 'geoctl_ros'
        assert node.get('exec') in _console_scripts(), node.get('exec')
        # the parameter file is passed as --params-file (a missing one then stops the node)
        assert not list(node.iter('param')), 'a param element only warns on a missing file'
        # (followed by more parameter files and -p overrides of the launch's arguments, at most)
        ros_args = node.get('ros_args')
        # (an override may be node-scoped, node:name:=value, as rcl reads it)
        assert re.fullmatch(r'(?:--params-file (?:\$\(var \w+\)|\S+))'
                            r'(?: --params-file (?:\$\(var \w+\)|\S+))*'
                            r'(?: -p (?:\w+:)?[\w.]+:=(?:\$\(var \w+\)|[\w.]+))*',
                            ros_args), ros_args
        for src in re.findall(r'--params-file (\$\(var \w+\)|\S+)', ros_args):
            for _ in range(3):                    # an argument whose default is another's
                m = re.fullmatch(r'\$\(var (\w+)\)', src)
                src = args[m.group(1)] if m else src
            path = src.replace('$(find-pkg-share geoctl_ros)', ROOT)
            assert os.path.isfile(path), src
        assert node.get('exec_name') == node.get('exec')    # labelled so under a prefix too
        for remap in node.iter('remap'):
            assert remap.get('from') in subscribed[node.get('exec')], remap.get('from')
    # installed where ros2 launch looks for them
    assert "('share/' + PACKAGE + '/launch'" in open(os.path.join(ROOT, 'setup.py')).read()


# --- the flight package and the tools: what each depends on -------------------------------------
# The flight package's run-time dependencies, the vehicle's: the Python modules it imports, each
# with the rosdep key package.xml declares it by (rosdistro's rosdep/python.yaml; pymavlink and
# rosbags have no Ubuntu package: their keys are pip's) and its name on the package index
# (setup.py's INSTALL_REQUIRES). rosbags is the recorder's (``record``, a node of the flight chain
# that the runbook starts before arming).
FLIGHT_MODULES = {'numpy': ('python3-numpy', 'numpy'), 'yaml': ('python3-yaml', 'pyyaml'),
                  'pymavlink': ('python3-pymavlink-pip', 'pymavlink'),
                  'smbus2': ('python3-smbus2', 'smbus2'),
                  'rosbags': ('python3-rosbags-pip', 'rosbags')}
# ROS 2's packages the flight package uses (from ROS 2, apt or the Jazzy wheels; not setup.py's):
# rclpy with its own interfaces, common_interfaces' messages, and ros2launch for the launch files
FLIGHT_ROS = {'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'rosgraph_msgs', 'std_msgs',
              'geometry_msgs', 'sensor_msgs', 'std_srvs', 'diagnostic_msgs', 'visualization_msgs'}
LAUNCH = 'ros2launch'
# the development tools' modules beyond those: setup.py's extra `tools` (by index name), which is
# never on the vehicle
TOOL_MODULES = {'matplotlib': 'matplotlib', 'dask': 'dask', 'distributed': 'distributed',
                'optuna': 'optuna', 'staliro': 'psy-taliro', 'rtamt': 'rtamt', 'scipy': 'scipy',
                'hypothesis': 'hypothesis'}
# ROS 2 packages that come with rclpy and the `ros2` command, which the tools and tests use too
ROS_BESIDE = {'ament_index_python', 'launch_ros'}
# the flight package's modules: the layers the flight chain is made of (the nodes and what they
# import), and the commands that check a parameter file and a recorded flight on the vehicle
# (scenario, report: their figures are the extra's) with the tools' front door
FLIGHT_LAYERS = ('core', 'params', 'sim', 'esc', 'mavlink', 'nodes', 'records')
FLIGHT_CLI = ('cli', 'cli.args', 'cli.scenario', 'cli.report', 'cli.tools')


def _setup_lists():
    """setup.py's INSTALL_REQUIRES, the extras and the console scripts {name: target}."""
    tree = ast.parse(open(os.path.join(ROOT, 'setup.py')).read())
    consts = {t.id: ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
              for t in n.targets if isinstance(t, ast.Name) and t.id.isupper()
              and isinstance(n.value, (ast.List, ast.Dict, ast.Constant))}
    call = next(n for n in ast.walk(tree) if isinstance(n, ast.Call)
                and getattr(n.func, 'id', None) == 'setup')
    kw = {k.arg: k.value for k in call.keywords}
    install = consts[kw['install_requires'].id]
    extras = {ast.literal_eval(k): (consts[v.id] if isinstance(v, ast.Name)
                                    else ast.literal_eval(v))
              for k, v in zip(kw['extras_require'].keys, kw['extras_require'].values)}
    scripts = dict(re.fullmatch(r'(\w+) = ([\w.]+:\w+)', e).groups()
                   for e in ast.literal_eval(kw['entry_points'])['console_scripts'])
    return install, extras, scripts


def _name(requirement):
    """A requirement's distribution name, normalised (PEP 503)."""
    return re.sub(r'[-_.]+', '-', re.match(r'[A-Za-z0-9_.-]+', requirement).group(0)).lower()


def _pins(path):
    """{normalised name: version} of a requirements file's ``name==version`` lines."""
    pins = {}
    for line in open(path):
        m = re.match(r'([A-Za-z0-9_.-]+)(?:\[[\w,]+\])?==(\S+)', line.strip())
        if m:
            pins[_name(m.group(1))] = m.group(2)
    return pins


def _exec_depends():
    xml = open(os.path.join(ROOT, 'package.xml')).read()
    return (set(re.findall(r'<exec_depend>([\w-]+)</exec_depend>', xml)),
            set(re.findall(r'<test_depend>([\w-]+)</test_depend>', xml)))


def _third_party(modules):
    return {m.split('.')[0] for m in modules} - set(sys.stdlib_module_names) - {'geoctl_ros'}


def _flight_modules():
    return {name: path for name, path in package_modules().items()
            if name.count('.') and (name.split('.')[1] in FLIGHT_LAYERS
                                    or name.split('.', 1)[1] in FLIGHT_CLI)}


@functools.lru_cache(maxsize=None)
def _imports_of(path, lazy):
    """``module_level_imports`` of a file, parsed once per run (every module's walk reads the
    package's common modules again).
    """
    return tuple(module_level_imports(path, functions=lazy))


def _on_import(name, files, lazy=False):
    """The third-party modules that importing the package's module NAME imports, through every
    module of the package it imports on the way (and their packages' __init__s); with lazy, the
    imports inside functions too (what running it may import).
    """
    def scan(path):
        return _imports_of(path, lazy)
    parts = name.split('.')
    stack, seen, found = ['.'.join(parts[:i]) for i in range(1, len(parts) + 1)], set(), set()
    while stack:
        m = stack.pop()
        if m in seen:
            continue
        seen.add(m)
        for mod in scan(files[m]):
            parts = mod.split('.')
            if parts[0] != 'geoctl_ros':
                found |= _third_party([mod])
                continue
            while parts and '.'.join(parts) not in files:
                parts.pop()
            stack += ['.'.join(parts[:i]) for i in range(1, len(parts) + 1)]
    return found


@odroid
def test_the_flight_packages_run_time_dependencies_are_the_vehicles_and_nothing_else():
    """package.xml's exec_depends are the flight package's (FLIGHT_MODULES' keys, FLIGHT_ROS and
    ros2launch) and setup.py's INSTALL_REQUIRES their index names: exactly what the flight
    modules import, nothing more, nothing less; and requirements-odroid.txt, the vehicle's
    stack, pins each of them and none of the tools' (so that a fresh venv of it with this
    package holds no Dask, matplotlib, ...: the README's ODROID quick start has none either).
    """
    exec_deps, _ = _exec_depends()
    install, _, _ = _setup_lists()
    imported = set()
    for path in _flight_modules().values():
        imported |= _third_party(imported_modules(path))
    unknown = imported - set(FLIGHT_MODULES) - FLIGHT_ROS
    assert not unknown, 'the flight package imports %s: not a flight dependency' % sorted(unknown)
    assert imported == set(FLIGHT_MODULES) | FLIGHT_ROS, 'declared but not imported: %s' % sorted(
        set(FLIGHT_MODULES) | FLIGHT_ROS - imported)
    assert exec_deps == {key for key, _ in FLIGHT_MODULES.values()} | FLIGHT_ROS | {LAUNCH}
    assert {_name(r) for r in install} == {pip for _, pip in FLIGHT_MODULES.values()}
    vehicle = _pins(os.path.join(ROOT, 'requirements-odroid.txt'))
    assert {pip for _, pip in FLIGHT_MODULES.values()} <= set(vehicle)
    tools = {_name(n) for n in TOOL_MODULES.values()}
    assert not tools & set(vehicle), sorted(tools & set(vehicle))
    assert os.path.isfile(os.path.join(ROOT, 'LICENSE'))
    assert 'BSD 3-Clause' in open(os.path.join(ROOT, 'LICENSE')).read()


# (parsed, not imported: the same on either stack, so the development stack's alone; the tools'
# commands without the extra run on both, test_without_the_extra_each_tool_says_in_one_line...)
def test_no_flight_module_imports_a_tool_dependency_on_import():
    """No module of the flight package imports matplotlib, Dask, Optuna, ... when it is imported,
    directly or through the package's modules it imports (parsed; imports inside functions are
    the figures' of scenario and report, drawn with the extra only); the console scripts of the
    flight package are its modules', and the tools' go through their front door
    (geoctl_ros.cli.tools), which says in one line where they run. The check sees a planted one.
    """
    files = package_modules()
    flight = _flight_modules()
    assert {'geoctl_ros.nodes.controller', 'geoctl_ros.records.bag',
            'geoctl_ros.cli.scenario'} <= set(flight)
    bad = {name: sorted(_on_import(name, files) & set(TOOL_MODULES)) for name in sorted(flight)}
    bad = {name: mods for name, mods in bad.items() if mods}
    assert not bad, bad
    assert _on_import('geoctl_ros.plots.scenario', files) & set(TOOL_MODULES)    # it sees one
    _, _, scripts = _setup_lists()
    from geoctl_ros.cli import tools  # noqa: PLC0415  (as the test reads it, after the above)
    for name, target in scripts.items():
        module, func = target.split(':')
        if name in tools.TOOLS:
            assert target == 'geoctl_ros.cli.tools:%s' % name, (name, target)
            assert getattr(tools, func)
        else:
            assert module in flight, (name, target)


# what a command's modules import inside a function that the command never calls (the check above
# parses by module): the benchmark reads campaign.tune's GAINS; only tune's study imports optuna
NEVER_CALLED = {'benchmark': {'optuna'}}


def test_the_tools_dependencies_are_the_extra_tools_pinned_as_requirements_txt():
    """setup.py's extra ``tools`` is exactly the tools' modules, each pinned to requirements.txt's
    version (the development stack gets it); every other import of the package is a flight or a
    ROS package; and each tool command's front door knows every tool module the command may
    import (geoctl_ros.cli.tools.TOOLS), so that it refuses before a traceback would.
    """
    from geoctl_ros.cli import tools  # noqa: PLC0415
    _, extras, _ = _setup_lists()
    pins = _pins(os.path.join(ROOT, 'requirements.txt'))
    extra = {_name(r): r.split('==', 1)[1] for r in extras[tools.EXTRA] if '==' in r}
    assert len(extra) == len(extras[tools.EXTRA]), 'pin every one: %s' % extras[tools.EXTRA]
    assert set(extra) == {_name(n) for n in TOOL_MODULES.values()}
    assert {n: pins.get(n) for n in extra} == extra, 'requirements.txt pins them otherwise'
    files = package_modules()
    imported = set()
    for path in files.values():
        imported |= _third_party(imported_modules(path))
    unknown = imported - set(FLIGHT_MODULES) - FLIGHT_ROS - set(TOOL_MODULES) - ROS_BESIDE
    assert not unknown, 'the package imports %s: add it to the flight package or the extra' % (
        sorted(unknown))
    for command, (_, needs) in tools.TOOLS.items():
        # what it imports on start, and what it may import as it runs (matplotlib aside: the
        # figures of those that run without it are drawn where geoctl_ros.plots.available)
        used = _on_import('geoctl_ros.cli.' + command, files) | (
            _on_import('geoctl_ros.cli.' + command, files, lazy=True) - {'matplotlib'}
            - NEVER_CALLED.get(command, set()))
        used &= set(TOOL_MODULES)
        assert used <= set(needs), '%s imports %s: add them to cli.tools.TOOLS' % (
            command, sorted(used - set(needs)))
    assert {tools.DISTRIBUTIONS.get(m, m) for m in TOOL_MODULES} == set(TOOL_MODULES.values())


@odroid
def test_the_tests_imports_are_declared():
    """Every import of the tests is the flight package's, a test_depend of package.xml, or a
    tool's (those tests skip without the extra, which the vehicle has not).
    """
    exec_deps, test_deps = _exec_depends()
    keys = {module: key for module, (key, _) in FLIGHT_MODULES.items()}
    keys.update({'pytest': 'python3-pytest'})
    imported = set()
    for dirpath, _, names in os.walk(os.path.join(ROOT, 'test')):
        imported |= {m for f in names if f.endswith('.py')
                     for m in _third_party(imported_modules(os.path.join(dirpath, f)))}
    local = {f[:-3] for d in ('test', 'benchmarks') for f in os.listdir(os.path.join(ROOT, d))
             if f.endswith('.py')}                      # the tests' own helpers
    imported -= local | set(TOOL_MODULES) | ROS_BESIDE
    declared = exec_deps | test_deps
    assert {keys.get(m, m) for m in imported} <= declared, sorted(
        {keys.get(m, m) for m in imported} - declared)


BLOCK_TOOLS = """
import contextlib, io, json, sys
class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in %r:
            raise ImportError('blocked: ' + name)
sys.meta_path.insert(0, Block())
import importlib.util
_find_spec = importlib.util.find_spec
def find_spec(name, package=None):
    if name.split('.')[0] in %r:
        return None
    return _find_spec(name, package)
importlib.util.find_spec = find_spec
"""

TOOLS_WITHOUT_EXTRA = """
from geoctl_ros.cli import tools
out = {}
for command in tools.TOOLS:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = tools.run(command, ['--help'])
        except SystemExit as e:
            code = e.code
    out[command] = [code, err.getvalue()]
out['imported'] = sorted(m for m in sys.modules if m.split('.')[0] in %r)
print(json.dumps(out))
"""


@odroid
def test_without_the_extra_each_tool_says_in_one_line_where_it_runs():
    """With the tools' modules made unimportable (as on the vehicle's stack), every tool command
    (console script or ./run's) given --help says in one line that it is a development tool and
    how to get the extra, exits 2, and has imported none of them; one that needs nothing of the
    extra (soak, sensors) runs, and its help says where it runs.
    """
    from geoctl_ros.cli import tools  # noqa: PLC0415
    blocked = sorted(TOOL_MODULES)
    code = BLOCK_TOOLS % (blocked, blocked) + TOOLS_WITHOUT_EXTRA % (blocked,)
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, cwd=ROOT,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out.pop('imported') == []
    for command, (rc, err) in out.items():
        if tools.TOOLS[command][1]:
            assert rc == 2 and len(err.strip().splitlines()) == 1, (command, rc, err)
            assert 'development tool' in err and "'.[tools]'" in err and 'Traceback' not in err
            assert err.startswith(command + ': ')
        else:
            assert rc == 0 and not err, (command, rc, err)


SCENARIO_WITHOUT_MATPLOTLIB = """
from geoctl_ros.cli import scenario
sys.exit(scenario.main([sys.argv[1], '--out', sys.argv[2], '--duration', '0.2']))
"""


@odroid
def test_scenario_runs_on_the_vehicle_without_matplotlib_and_says_the_figures_are_skipped(
        tmp_path):
    """``scenario`` (the runbook's check of a parameter file on the vehicle) writes its summary
    and history without matplotlib, and says in one line that the figures need the extra.
    """
    blocked = sorted(TOOL_MODULES)
    code = BLOCK_TOOLS % (blocked, blocked) + SCENARIO_WITHOUT_MATPLOTLIB
    path = os.path.join(ROOT, 'config', 'scenarios', 'testbed_yaw90.yaml')
    r = subprocess.run([sys.executable, '-c', code, path, str(tmp_path)], capture_output=True,
                       text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    assert 'Traceback' not in r.stderr
    assert [line for line in r.stderr.splitlines() if line.startswith('scenario:')] == [
        "scenario: no figures: matplotlib is not installed here (the extra 'tools': pip install "
        "-e '.[tools]' in a clone, or draw them on a development machine); the rest is written"]
    assert sorted(os.listdir(tmp_path)) == ['history.csv', 'summary.json']
    assert 'constraint kept' in r.stdout


@pytest.mark.skipif(shutil.which('colcon', path=os.path.dirname(sys.executable)) is None,
                    reason='no colcon in this stack (requirements-odroid.txt has it)')
@pytest.mark.skipif(int(np.__version__.split('.')[0]) >= 2,
                    reason="the build as on the vehicle is checked on the vehicle's stack; here "
                           'the launch tests build the package with colcon')
@odroid
def test_colcon_builds_installs_and_tests_the_package_as_on_the_vehicle(tmp_path):
    """The apt path's last two steps, in a workspace of its own: `colcon build` installs every
    console script where `ros2 run` looks and the files the launch files name (a tool's, without
    its extra, says so in one line), and `colcon test` runs the package's pytest suite (one
    module of it here).
    """
    ws = Workspace(str(tmp_path / 'ws'))
    colcon, env = ws.colcon, ws.env
    colcon('build', '--packages-select', 'geoctl_ros')
    prefix = pathlib.Path(ws.prefix)
    assert set(os.listdir(prefix / 'lib' / 'geoctl_ros')) >= _console_scripts()
    share = prefix / 'share' / 'geoctl_ros'
    for f in ('package.xml', 'config/testbed.yaml', 'config/dds/fastdds_loopback.xml',
              'launch/testbed.launch.xml', 'launch/sil.launch.xml'):
        assert (share / f).is_file(), f
    index = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'geoctl_ros'
    assert index.is_file()
    r = subprocess.run([str(prefix / 'lib' / 'geoctl_ros' / 'scenario'), '--help'], env=env,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and 'usage' in r.stdout, r.stderr
    # a tool's script, where its extra is not installed (the vehicle's stack): one line
    r = subprocess.run([str(prefix / 'lib' / 'geoctl_ros' / 'tune'), '--help'], env=env,
                       capture_output=True, text=True, timeout=60)
    if importlib.util.find_spec('optuna') is None:
        assert r.returncode == 2 and not r.stdout, r.stdout
        assert r.stderr.startswith('tune: a development tool (gain tuning)'), r.stderr
        assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    else:
        assert r.returncode == 0 and 'usage' in r.stdout, r.stderr
    colcon('test', '--packages-select', 'geoctl_ros', '--pytest-args', 'test/test_so3.py')
    summary = colcon('test-result', '--all')
    m = re.search(r'(\d+) tests, 0 errors, 0 failures', summary)
    assert m and int(m.group(1)) >= 5, summary

NUMPY_1_26 = os.path.join(ROOT, 'test', 'data', 'numpy-1.26.txt')


def _numpy_1_26():
    with open(NUMPY_1_26) as fh:
        return {line.strip() for line in fh if line.strip() and not line.startswith('#')}


@odroid
def test_the_code_uses_nothing_that_numpy_1_26_lacks():
    """The vehicle's numpy (Ubuntu 24.04: 1.26.4) has every numpy name the package, its tests
    and benchmarks use; a miss is named with its file and line, not found deep in a flight.
    """
    have = _numpy_1_26()
    newer = {n[len('ndarray.'):] for n in numpy_api.names() if n.startswith('ndarray.')} - {
        n[len('ndarray.'):] for n in have if n.startswith('ndarray.')}
    problems = []
    for top in ('geoctl_ros', 'test', 'benchmarks'):
        for dirpath, _, files in os.walk(os.path.join(ROOT, top)):
            for f in sorted(files):
                if f.endswith('.py'):
                    path = os.path.join(dirpath, f)
                    with open(path) as fh:
                        source = fh.read()
                    problems += ['%s:%d: numpy 1.26 (Ubuntu 24.04) has no %s'
                                 % (os.path.relpath(path, ROOT), line, name)
                                 for line, name in numpy_api.missing(source, have, newer)]
    assert not problems, '\n'.join(problems)


@odroid
def test_the_numpy_check_finds_what_1_26_lacks_and_only_that():
    source = ('import numpy as np\n'
              'from numpy import linalg as la\n'
              'a = np.eye(3)\n'
              'b = np.matvec(a, np.linalg.norm(a[0]) * np.ones(3))\n'
              'c = a.mT @ la.inv(a) + np.linalg.matrix_transpose(a)\n'
              'd = np.multiply.outer(a, a).T\n')
    assert numpy_api.missing(source, _numpy_1_26(), {'mT', 'device'}) == [
        (4, 'numpy.matvec'), (5, 'ndarray.mT'), (5, 'numpy.linalg.matrix_transpose')]


@odroid
@pytest.mark.skipif(not np.__version__.startswith('1.26.'), reason='needs numpy 1.26 itself')
def test_the_committed_numpy_1_26_names_are_numpy_1_26s():
    assert set(numpy_api.names()) == _numpy_1_26(), 'regenerate: python test/numpy_api.py > %s' % (
        os.path.relpath(NUMPY_1_26, ROOT))


def _ruff():
    ruff = shutil.which('ruff', path=os.path.dirname(sys.executable))
    if ruff is None:
        pytest.skip('ruff is installed on the development stack only (requirements.txt)')
    return ruff


@odroid
def test_every_file_of_the_tree_is_clean_under_the_linter():
    """ruff with ruff.toml (ament_flake8's rules and pep257's) over the package, tests, benchmarks
    and launch files' Python; a new violation fails here with its file, line and rule.
    """
    r = subprocess.run([_ruff(), 'check', '--no-cache', '--output-format', 'concise', '.'],
                       cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


@odroid
def test_the_linter_finds_what_the_rules_forbid():
    planted = ('"""A module."""\n'
               'import os\n\n\n'
               'def f():\n'
               '    import sys\n'
               '    return "%s" % sys.argv\n\n\n'
               'X = 1  # ' + 'x' * 100 + '\n')
    r = subprocess.run([_ruff(), 'check', '--no-cache', '--output-format', 'concise',
                        '--stdin-filename', os.path.join(ROOT, 'geoctl_ros', 'planted.py'), '-'],
                       cwd=ROOT, input=planted, capture_output=True, text=True)
    assert r.returncode == 1
    found = set(re.findall(r'\b([A-Z]+[0-9]+)\b', r.stdout))
    assert {'F401', 'PLC0415', 'Q000', 'E501'} <= found, r.stdout


@odroid
def test_the_rclpy_free_layers_are_clean_under_mypy(tmp_path):
    """mypy (mypy.ini: core, params, sim, esc and falsify; core/ strictly, with --strict's
    per-module flags) finds no type error; a planted one it finds.
    """
    if importlib.util.find_spec('mypy') is None:
        pytest.skip('mypy is installed on the development stack only (requirements.txt)')
    r = subprocess.run([sys.executable, '-m', 'mypy', '--no-incremental', '--cache-dir',
                        os.devnull], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    planted = tmp_path / 'planted.py'
    planted.write_text('def f(x: int) -> str:\n    return x\n')
    r = subprocess.run([sys.executable, '-m', 'mypy', '--no-incremental', '--cache-dir',
                        os.devnull, '--config-file', os.devnull, str(planted)], cwd=ROOT,
                       capture_output=True, text=True)
    assert r.returncode == 1 and 'Incompatible return value' in r.stdout, r.stdout


@odroid
def test_every_public_function_of_the_typed_layers_has_type_hints():
    """Every public function and method of core, params, sim and esc (mypy.ini's layers) says
    the types of its arguments and of what it returns, so that mypy checks it and its callers.
    """
    bare = []
    for layer in ('core', 'params', 'sim', 'esc'):
        for path in sorted(pathlib.Path(PKG, layer).rglob('*.py')):
            for node in ast.walk(ast.parse(path.read_text())):
                if not isinstance(node, ast.FunctionDef) or node.name.startswith('_'):
                    continue
                args = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
                if node.returns is None or any(a.annotation is None for a in args
                                               if a.arg not in ('self', 'cls')):
                    bare.append('%s/%s:%d %s' % (layer, path.name, node.lineno, node.name))
    assert not bare, bare


@odroid
def test_no_signature_in_core_takes_or_gives_any_or_object():
    """core's functions say what they take and give: no argument or result of any of them
    (private ones too) is typed Any or object, written plainly or inside another type. (Only the
    diagnostics codec's table of mixed fields holds Any, in its Key's fields.)
    """
    vague = []
    for path in sorted(pathlib.Path(PKG, 'core').rglob('*.py')):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            args = node.args
            annotations = [a.annotation for a in args.posonlyargs + args.args + args.kwonlyargs
                           + [args.vararg, args.kwarg] if a is not None and a.annotation]
            for annotation in annotations + ([node.returns] if node.returns else []):
                text = (annotation.value if isinstance(annotation, ast.Constant)
                        and isinstance(annotation.value, str) else ast.unparse(annotation))
                names = {n.id for n in ast.walk(ast.parse(text, mode='eval'))
                         if isinstance(n, ast.Name)}
                if names & {'Any', 'object'}:
                    vague.append('%s:%d %s: %s' % (path.relative_to(PKG), node.lineno,
                                                   node.name, text))
    assert not vague, vague


INSTALLED_CONFIG = """
import sys
from geoctl_ros.sil import rosenv
print(rosenv.config_dir())
"""


@odroid
def test_the_scripts_find_the_config_pip_installed_without_a_sourced_workspace(tmp_path):
    """Issue (hostile input): after ``pip install`` outside a sourced workspace, ``campaign``
    died with "Environment variable 'AMENT_PREFIX_PATH' is not set or empty". Here the package
    is laid out as pip installs it (the code in site-packages, the config under the venv's
    share/geoctl_ros) in a venv of its own, with no AMENT_PREFIX_PATH: the config is found; and
    with no config anywhere the script stops with one line saying to source the workspace.
    """
    venv = tmp_path / 'venv'
    subprocess.run([sys.executable, '-m', 'venv', '--without-pip', str(venv)], check=True)
    site = tmp_path / 'site'
    shutil.copytree(os.path.join(ROOT, 'geoctl_ros'), site / 'geoctl_ros',
                    ignore=shutil.ignore_patterns('__pycache__'))
    deps = [p for p in sys.path if p.endswith('site-packages')]
    env = {k: v for k, v in os.environ.items() if k != 'AMENT_PREFIX_PATH'}
    env['PYTHONPATH'] = os.pathsep.join([str(site)] + deps)
    python = str(venv / 'bin' / 'python')
    missing = subprocess.run([python, '-c', INSTALLED_CONFIG], env=env, capture_output=True,
                             cwd=str(tmp_path),
                             text=True, timeout=60)
    assert missing.returncode != 0 and 'Traceback' not in missing.stderr, missing.stderr
    assert len(missing.stderr.strip().splitlines()) == 1, missing.stderr
    assert 'source the workspace' in missing.stderr
    share = venv / 'share' / 'geoctl_ros' / 'config'
    shutil.copytree(os.path.join(ROOT, 'config'), share)
    found = subprocess.run([python, '-c', INSTALLED_CONFIG], env=env, capture_output=True,
                           cwd=str(tmp_path),
                           text=True, timeout=60)
    assert found.returncode == 0, found.stderr
    assert found.stdout.strip() == str(share)


def _anchor(heading):
    return re.sub(r'[^\w\- ]', '', heading.strip().lower()).replace(' ', '-')


@odroid
def test_every_link_of_the_readme_and_the_manual_leads_somewhere():
    """The README is a map and docs/ the manual: every relative link of theirs names a file that
    exists and, with a #fragment, a heading of that file.
    """
    pages = [os.path.join(ROOT, 'README.md')] + sorted(
        str(p) for p in pathlib.Path(ROOT, 'docs').glob('*.md'))
    broken = []
    for page in pages:
        text = open(page).read()
        for target in re.findall(r'\]\(([^)\s]+)\)', text):
            if re.match(r'[a-z]+:', target):
                continue                                    # https:, mailto:
            path, _, fragment = target.partition('#')
            full = os.path.normpath(os.path.join(os.path.dirname(page), path)) if path else page
            if not os.path.exists(full):
                broken.append('%s: %s' % (os.path.relpath(page, ROOT), target))
            elif fragment and full.endswith('.md'):
                headings = {_anchor(h) for h in re.findall(r'^#+ (.*)$', open(full).read(),
                                                           re.M)}
                if fragment not in headings:
                    broken.append('%s: %s' % (os.path.relpath(page, ROOT), target))
    assert not broken, broken
