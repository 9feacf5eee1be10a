"""The package as a maintainer and a lab receive it: launch files that name only what exists, the
packaging metadata, colcon as on the vehicle, the numpy 1.26 and linter and mypy checks, the
scripts pip-installed, and the manual's links. (Its layers: test_layers.py.)

The launch files are checked here for what needs no launcher (they parse, and every executable,
parameter file and remapping they name exists); ``test_launch.py`` runs them with ``ros2 launch``.
"""
import ast
import importlib.util
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
from source_support import PKG, ROOT, imported_modules
from workspace import Workspace

pytestmark = pytest.mark.odroid



def _console_scripts():
    text = open(os.path.join(ROOT, 'setup.py')).read()
    return set(re.findall(r"'(\w+) = geoctl_ros\.[\w.]+:main'", text))


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
        # (followed by -p overrides of the launch's arguments, at most)
        src = re.fullmatch(r'--params-file (\$\(var \w+\)|\S+)'
                           r'(?: -p [\w.]+:=(?:\$\(var \w+\)|[\w.]+))*',
                           node.get('ros_args')).group(1)
        m = re.fullmatch(r'\$\(var (\w+)\)', src)
        src = args[m.group(1)] if m else src
        path = src.replace('$(find-pkg-share geoctl_ros)', ROOT)
        assert os.path.isfile(path), src
        assert node.get('exec_name') == node.get('exec')    # labelled so under a prefix too
        for remap in node.iter('remap'):
            assert remap.get('from') in subscribed[node.get('exec')], remap.get('from')
    # installed where ros2 launch looks for them
    assert "('share/' + PACKAGE + '/launch'" in open(os.path.join(ROOT, 'setup.py')).read()


# what `rosdep install` resolves for each import that is not a ROS package of the same name
# (keys from rosdistro's rosdep/python.yaml; pymavlink has no Ubuntu package, its key is pip's)
ROSDEP_KEYS = {'numpy': 'python3-numpy', 'yaml': 'python3-yaml',
               'matplotlib': 'python3-matplotlib', 'pymavlink': 'python3-pymavlink-pip',
               'pytest': 'python3-pytest', 'rosbags': 'python3-rosbags-pip',
               'dask': 'python3-dask', 'distributed': 'python3-distributed',
               'smbus2': 'python3-smbus2', 'hypothesis': 'python3-hypothesis'}
# imported by development tools only, never on the vehicle: not in package.xml, pinned in
# requirements.txt (`./run tune` and `./run falsify`: the gains are tuned, and the envelope
# attacked, on a development machine or a cluster)
DEVELOPMENT_ONLY = {'optuna', 'rtamt', 'staliro', 'scipy'}
ROS_PACKAGES = {'rclpy', 'rcl_interfaces', 'builtin_interfaces', 'ament_index_python', 'std_msgs',
                'geometry_msgs', 'sensor_msgs', 'std_srvs', 'diagnostic_msgs', 'rosgraph_msgs',
                'launch_ros', 'visualization_msgs'}


def _third_party_imports(top):
    found = set()
    for dirpath, _, files in os.walk(os.path.join(ROOT, top)):
        for f in files:
            if f.endswith('.py'):
                found |= {m.split('.')[0] for m in imported_modules(os.path.join(dirpath, f))}
    local = {f[:-3] for d in ('test', 'benchmarks') for f in os.listdir(os.path.join(ROOT, d))
             if f.endswith('.py')}                      # the tests' own helpers
    return found - set(sys.stdlib_module_names) - local - {'geoctl_ros'}


def test_package_xml_declares_what_the_code_imports():
    """Every import of the package (exec_depend) and of its tests (test_depend) is declared
    with the key a lab's `rosdep install` resolves on Ubuntu 24.04.
    """
    xml = open(os.path.join(ROOT, 'package.xml')).read()
    exec_deps = set(re.findall(r'<exec_depend>([\w-]+)</exec_depend>', xml))
    test_deps = set(re.findall(r'<test_depend>([\w-]+)</test_depend>', xml)) | exec_deps
    for top, declared in (('geoctl_ros', exec_deps), ('test', test_deps)):
        imported = _third_party_imports(top)
        imported -= DEVELOPMENT_ONLY
        unknown = imported - ROS_PACKAGES - set(ROSDEP_KEYS)
        assert not unknown, '%s imports %s: add its rosdep key here and to package.xml' % (
            top, sorted(unknown))
        keys = {ROSDEP_KEYS.get(m, m) for m in imported}
        assert keys <= declared, '%s: package.xml lacks %s' % (top, sorted(keys - declared))
    assert os.path.isfile(os.path.join(ROOT, 'LICENSE'))
    assert 'BSD 3-Clause' in open(os.path.join(ROOT, 'LICENSE')).read()


@pytest.mark.skipif(shutil.which('colcon', path=os.path.dirname(sys.executable)) is None,
                    reason='no colcon in this stack (requirements-odroid.txt has it)')
@pytest.mark.skipif(int(np.__version__.split('.')[0]) >= 2,
                    reason="the build as on the vehicle is checked on the vehicle's stack; here "
                           'the launch tests build the package with colcon')
def test_colcon_builds_installs_and_tests_the_package_as_on_the_vehicle(tmp_path):
    """The apt path's last two steps, in a workspace of its own: `colcon build` installs every
    console script where `ros2 run` looks and the files the launch files name, and `colcon
    test` runs the package's pytest suite (one module of it here).
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
    colcon('test', '--packages-select', 'geoctl_ros', '--pytest-args', 'test/test_so3.py')
    summary = colcon('test-result', '--all')
    m = re.search(r'(\d+) tests, 0 errors, 0 failures', summary)
    assert m and int(m.group(1)) >= 5, summary

NUMPY_1_26 = os.path.join(ROOT, 'test', 'data', 'numpy-1.26.txt')


def _numpy_1_26():
    with open(NUMPY_1_26) as fh:
        return {line.strip() for line in fh if line.strip() and not line.startswith('#')}


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


def test_the_numpy_check_finds_what_1_26_lacks_and_only_that():
    source = ('import numpy as np\n'
              'from numpy import linalg as la\n'
              'a = np.eye(3)\n'
              'b = np.matvec(a, np.linalg.norm(a[0]) * np.ones(3))\n'
              'c = a.mT @ la.inv(a) + np.linalg.matrix_transpose(a)\n'
              'd = np.multiply.outer(a, a).T\n')
    assert numpy_api.missing(source, _numpy_1_26(), {'mT', 'device'}) == [
        (4, 'numpy.matvec'), (5, 'ndarray.mT'), (5, 'numpy.linalg.matrix_transpose')]


@pytest.mark.skipif(not np.__version__.startswith('1.26.'), reason='needs numpy 1.26 itself')
def test_the_committed_numpy_1_26_names_are_numpy_1_26s():
    assert set(numpy_api.names()) == _numpy_1_26(), 'regenerate: python test/numpy_api.py > %s' % (
        os.path.relpath(NUMPY_1_26, ROOT))


def _ruff():
    ruff = shutil.which('ruff', path=os.path.dirname(sys.executable))
    if ruff is None:
        pytest.skip('ruff is installed on the development stack only (requirements.txt)')
    return ruff


def test_every_file_of_the_tree_is_clean_under_the_linter():
    """ruff with ruff.toml (ament_flake8's rules and pep257's) over the package, tests, benchmarks
    and launch files' Python; a new violation fails here with its file, line and rule.
    """
    r = subprocess.run([_ruff(), 'check', '--no-cache', '--output-format', 'concise', '.'],
                       cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


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


def test_the_rclpy_free_layers_are_clean_under_mypy(tmp_path):
    """mypy (mypy.ini: core, params, sim and esc) finds no type error; a planted one it finds."""
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


INSTALLED_CONFIG = """
import sys
from geoctl_ros.sil import rosenv
print(rosenv.config_dir())
"""


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
