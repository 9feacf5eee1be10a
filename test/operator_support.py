"""The operator reference's check (test_operator_reference.py): every message the controller, the
ESC node and the MAVLink bridge can show an operator, collected from the source with ``ast``, and
the rows of docs/operator.md that say what to do about each.

A message is collected where it leaves the program (the **sinks**, looked for in every file of
``SOURCES``):

- a log line at WARN or above: ``get_logger().warning/warn/error/fatal(m)``, a local alias of one
  (``log = ... get_logger().warning``), ``RefusalLog.warn(prefix, reason)`` (prefix + reason),
  and ``sys.stderr.write(m)`` (a node that cannot start);
- a reply: ``ArmResult(ok, m)`` (``~/arm``), ``response.message = m`` (a service's answer),
  ``self._text(m, ...)`` (the bridge's STATUSTEXT to the ground station);
- /diagnostics: ``DiagnosticStatus(message=m)``, ``Status(level, m, ...)``, ``EscReport(level, m,
  ...)``;
- a failsafe's reason: ``failsafe(m)``; an exception whose text is shown: ``EscStartError(m)``,
  ``SigningKeyError(m)``, ``ConfigError([(name, m), ...])`` (a node that stops at start, or a
  parameter change refused);

and in the **producers** (``PRODUCERS``: the functions whose sentences those sinks pass on, the
``*_problem`` functions, the arming checks, the diagnostics' composers): every string they return
(a list's or a tuple's elements too), append, insert or add to a list, assign to a name that
holds a message (``MESSAGE_NAMES``) or give an exception (``super().__init__(m)``), and the
default of a ``reason`` parameter.

Each becomes a template: %-fields, f-string and str.format fields, and whatever is not a string
the collector can follow (a variable, a call) become wildcards; names are followed to their local
assignments, to module constants, through ``failsafe``'s one-line body, and, where the name
takes a few known texts (a stream's name, a loop over a table: ``EXPANSIONS``), to each of them. A
sink whose text is all wildcard passes on a sentence made elsewhere: its site must be listed in
``FORWARDED`` (with where the sentence is made), so that a new one is not missed, and every entry
there must still be such a site. So must whatever the composers (``COMPOSERS``: the functions that
build a status's or the arming checks' list of messages) add to their lists without a template.

In docs/operator.md, a message is found in a table that has a "what to do" column, as a code span
of the row's first cell (```...``` there stands for text that varies) that some text matches as
well as the template, in a row whose "what to do" (and "level", where the table has one) is not
empty. A span must begin with words (not ```...```), and a template that begins with a field is
found only in a span that has its first words as written. The diagnostics keys are found the same
way in the tables whose first column is "key" (the keys of the three codecs). The other way round,
every span of a row (but the INFO rows) must show a message or a key of the code.
"""
import ast
from collections import deque
import os
import re
from typing import Dict, Iterable, List, NamedTuple, Optional, Set, Tuple

from source_support import PKG, ROOT

OPERATOR_MD = os.path.join(ROOT, 'docs', 'operator.md')
W = '\x00'                   # a template's wildcard: text that varies

# The files whose messages an operator sees, by node (paths under geoctl_ros/).
SOURCES = {
    'controller': [
        'nodes/controller.py', 'nodes/runtime.py', 'nodes/realtime.py',
        'core/telemetry/scheduling.py', 'core/supervisor/loop.py',
        'core/supervisor/loop_status.py', 'core/supervisor/preflight.py',
        'core/supervisor/safety.py', 'core/actuation/esc_wire.py', 'core/sensors/consistency.py',
        'core/geometry/quaternions.py',
        'core/law/feasibility.py',
        'core/law/gains.py', 'core/actuation/airframe.py', 'core/actuation/allocation.py',
        'core/telemetry/diagnostics.py', 'params/validate.py', 'params/param.py'],
    'esc_i2c': ['nodes/esc_i2c.py', 'esc/driver.py', 'esc/health.py', 'esc/protocol.py'],
    'mavlink_bridge': [
        'nodes/mavlink_bridge.py', 'nodes/mavlink_calls.py', 'nodes/autopilot_imu.py',
        'mavlink/health.py', 'mavlink/controller_view.py', 'mavlink/signing.py',
        'mavlink/vehicle.py'],
    'operator commands': ['nodes/commands.py'],     # setpoint, stop: what they print
}

# The functions whose sentences the sinks pass on (qualified names in their file).
PRODUCERS = {
    'nodes/controller.py': ('ControllerNode._unconfigured', 'ControllerNode._other_commanders'),
    'core/supervisor/loop.py': ('ControlLoop.offer_esc_health', 'ControlLoop.request_setpoint',
                                'ControlLoop.reconfiguration_problem', 'spool_movement'),
    'core/supervisor/loop_status.py': ('gap_notes', 'status'),
    'core/supervisor/preflight.py': ('arm_problems', 'takeover_problems'),
    'core/supervisor/safety.py': (
        'specific_force_problem',
        'angular_velocity_problem', 'esc_problem', 'Stream.offer', 'Stream.staleness',
        'Stream.stamp_note',
        'Stream.loss', 'Supervisor.__init__', 'Supervisor.arm', 'Supervisor.disarm'),
    'core/sensors/consistency.py': (
        'SensorAgreement.pose', 'SensorAgreement.arm_problems',
        'SensorAgreement._rest_problems', 'SensorAgreement._gravity_cause',
        'SensorAgreement._rate_cause', 'SensorAgreement._judge_rate',
        'SensorAgreement._judge_yaw', 'SensorAgreement._yaw_cause'),
    'core/actuation/esc_wire.py': ('motor_commands_problem', 'esc_report', 'esc_report_of'),
    'core/geometry/quaternions.py': ('quaternion_problem',),
    'core/law/feasibility.py': ('setpoint_problem',),
    'core/telemetry/diagnostics.py': ('failsafe',),
    'core/telemetry/scheduling.py': ('scheduling_problem',),
    'core/law/gains.py': ('GainCheck.message',),
    'core/actuation/airframe.py': ('check',),
    'core/actuation/allocation.py': ('Allocator.__init__',),
    'params/validate.py': ('change_problem',),
    'params/param.py': ('ConfigError.__init__',),
    'esc/driver.py': ('EscDriver.__init__', 'EscDriver.offer', 'EscDriver.targets',
                      'EscDriver.start_test', 'EscDriver.stop'),
    'esc/health.py': ('report',),
    'esc/protocol.py': ('state_problem',),
    'nodes/mavlink_calls.py': ('GroundStationReports._publish_diagnostics',),
    'nodes/autopilot_imu.py': ('AutopilotImu.health',),
    'mavlink/controller_view.py': ('ControllerView.take_attitude', 'ControllerView.take_rate',
                                   'ControllerView.take_commands', 'ControllerView.take_psi',
                                   'ControllerView.take_array'),
}
# The producers that compose a list of messages (a status's, the arming checks'): whatever they
# add to a list must give a template or be FORWARDED, so that a sentence made in a file the
# collector does not read cannot pass unseen.
COMPOSERS = {('core/supervisor/loop_status.py', 'status'),
             ('core/supervisor/loop_status.py', 'gap_notes'),
             ('core/supervisor/preflight.py', 'arm_problems'),
             ('esc/health.py', 'report'),
             ('nodes/mavlink_calls.py', 'GroundStationReports._publish_diagnostics')}
# In a producer, a string assigned to one of these (a variable or an attribute) is a message.
MESSAGE_NAMES = {'problem', 'message', 'why', 'reason', 'flight_note', 'foreign_refusal',
                 'refusal', 'setpoint_note'}

LOG_LEVELS = {'warning', 'warn', 'error', 'fatal'}          # WARN and above
EXCEPTIONS = {'EscStartError', 'SigningKeyError'}
# class -> the message's index (Say: a STATUSTEXT the bridge sends for the vehicle)
STATUS_CLASSES = {'ArmResult': 1, 'Status': 1, 'EscReport': 1, 'Say': 0}


def _tree(path):
    return ast.parse(open(os.path.join(PKG, path)).read())


def stream_names() -> List[str]:
    """The controller's input streams' names, as loop.py makes them (``Stream(name, ...)``)."""
    return [n.args[0].value for n in ast.walk(_tree('core/supervisor/loop.py'))
            if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)
            and n.func.id == 'Stream' and isinstance(n.args[0], ast.Constant)]


def loop_values(path: str, name: str) -> List[str]:
    """The strings a loop variable takes in a file: ``for ..., name, ... in ((...), ...)``, over
    a literal or a module constant.
    """
    tree = _tree(path)
    constants = {n.targets[0].id: n.value for n in tree.body if isinstance(n, ast.Assign)
                 and isinstance(n.targets[0], ast.Name)}
    for node in ast.walk(tree):
        if isinstance(node, ast.For) and isinstance(node.target, ast.Tuple):
            names = [t.id if isinstance(t, ast.Name) else None for t in node.target.elts]
            if name in names:
                rows = constants.get(node.iter.id) if isinstance(node.iter, ast.Name) \
                    else node.iter
                k = names.index(name)
                return [r.elts[k].value for r in rows.elts]
    raise AssertionError('no loop over %s in %s' % (name, path))


# Expressions (their source, in their file) that stand for one of a few known texts.
EXPANSIONS = {
    ('core/supervisor/loop_status.py', 's.name'): stream_names,     # pose, angular velocity
    ('core/supervisor/safety.py', 'self.name'): stream_names,
    ('core/sensors/consistency.py', 'words'):                       # the conventions guessed
        lambda: loop_values('core/sensors/consistency.py', 'words'),
    ('nodes/mavlink_bridge.py', 'topic'):                           # the topics it takes
        lambda: loop_values('nodes/mavlink_bridge.py', 'topic'),
    ('core/law/gains.py', 'verdict'): lambda: ['VIOLATES'],    # (the node logs it only then)
}

# The sinks whose text is all made elsewhere: (file, the argument's source) -> where it is made.
FORWARDED = {
    ('nodes/controller.py', 'self.loop.unconfigured'): 'ControllerNode._unconfigured',
    ('nodes/controller.py', 'check.message()'): 'GainCheck.message',
    ('nodes/controller.py', 'tick.state'): 'the failsafes: failsafe(...)',
    ('nodes/controller.py', 'result.message'): 'ArmResult(...) (the ~/arm reply)',
    ('nodes/controller.py', "'; '.join(self.loop.gap_notes(now))"): 'loop_status.gap_notes',
    ('nodes/controller.py', "[('armed', problem)]"): 'validate.change_problem',
    ('nodes/controller.py', "[('cones', problem)]"): 'ControlLoop.reconfiguration_problem',
    ('nodes/controller.py', "[('setpoint', problem)]"): 'setpoint_problem (a set point refused)',
    ('nodes/runtime.py', 'str(e)'): 'ConfigError (the parameters, docs/parameters.md)',
    ('nodes/runtime.py', 'problem'): 'scheduling_problem',
    ('nodes/esc_i2c.py', "[('esc.addresses', str(e))]"): 'EscStartError(...) in driver.start',
    ('nodes/esc_i2c.py', "[('esc_i2c', problem)]"): 'validate.change_problem',
    ('nodes/mavlink_bridge.py', "[('mavlink.signing_key_file', str(e))]"):
        'SigningKeyError(...) in signing.load_key',
    ('nodes/mavlink_bridge.py', 's.message'): "the controller's diagnostics message",
    ('nodes/mavlink_bridge.py', 'action.text'): 'Say(...) in mavlink/vehicle.py',
    ('mavlink/signing.py', "'%s: %s' % (path, e.strerror)"): "the key file's path and the "
        "system's reason (No such file or directory, ...)",
    ('nodes/esc_i2c.py', 'r.message'): 'esc.health.report',
    ('core/supervisor/loop.py', 'problem'): 'esc_problem',
    ('core/supervisor/loop.py', 'self.agreement.flight_note'): 'SensorAgreement.pose',
    ('core/supervisor/loop.py', 'moved'): 'spool_movement',
    ('core/supervisor/safety.py', 'problem'): 'Stream.loss',
    # what the composers add that is made elsewhere
    ('core/supervisor/loop_status.py', 'sup.reason'): 'Supervisor (its states), failsafe(...)',
    ('core/supervisor/loop_status.py', 'loop.unconfigured'): 'ControllerNode._unconfigured',
    ('core/supervisor/loop_status.py', 'stale'): 'Stream.staleness',
    ('core/supervisor/loop_status.py', 'untrusted'): 'Stream.stamp_note',
    ('core/supervisor/loop_status.py', 'escs'): 'esc_problem',
    ('core/supervisor/loop_status.py', 'lost'): 'Stream.loss',
    ('core/supervisor/loop_status.py', 'gap_notes(loop, now)'): 'loop_status.gap_notes',
    ('core/supervisor/loop_status.py', 'loop.setpoint_note'): 'ControlLoop.request_setpoint',
    ('core/supervisor/loop_status.py', 'other_commanders'): 'ControllerNode._other_commanders',
    ('core/supervisor/preflight.py', 'p'): 'ControllerNode._unconfigured and '
        '_other_commanders, esc_problem, Stream.staleness',
    ('core/supervisor/preflight.py', 'loop.agreement.arm_problems(now)'):
        'SensorAgreement.arm_problems',
    ('core/supervisor/preflight.py', 'takeover_problems(loop, now)'): 'takeover_problems',
    ('esc/health.py', '_esc_line(address, tel, driver.errors[i], missing, age)'):
        "the esc N keys' values, not messages",
    ('nodes/mavlink_calls.py', 'ap_warning'): 'AutopilotImu.health',
}


class Site(NamedTuple):
    """Where a message is made: file, line, and what kind of sink or producer."""

    path: str
    line: int
    kind: str


_FIELD = re.compile(r'%(?:\([^)]*\))?[-#0 +]*(?:\*|\d+)?(?:\.(?:\*|\d+))?[hlL]?'
                    r'([diouxXeEfFgGcrsa%])')
_BRACES = re.compile(r'\{[^{}]*\}')
_PRODUCT_MAX = 64             # templates one expression may stand for


def _collapse(text: str) -> str:
    return re.sub(W + '+', W, text)


def _product(parts: List[Set[str]]) -> Set[str]:
    out = {''}
    for options in parts:
        out = {a + b for a in out for b in options}
        if len(out) > _PRODUCT_MAX:
            raise ValueError('too many templates')
    return {_collapse(t) for t in out}


class Module:
    """One source file, parsed: its functions by qualified name and its string constants."""

    def __init__(self, path: str, text: str):
        self.path = path
        self.tree = ast.parse(text)
        self.functions: Dict[str, ast.AST] = {}
        self.parent_function: Dict[ast.AST, ast.AST] = {}
        self.constants: Dict[str, ast.AST] = {}
        for node in self.tree.body:
            if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(
                    node.targets[0], ast.Name):
                self.constants[node.targets[0].id] = node.value
        self._index(self.tree, '', None)

    def _index(self, node, prefix, function):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = prefix + child.name
                self.functions.setdefault(name, child)
                self.parent_function[child] = function
                self._index(child, name + '.', child)
            elif isinstance(child, ast.ClassDef):
                self._index(child, prefix + child.name + '.', function)
            else:
                self.parent_function[child] = function
                self._index(child, prefix, function)

    def source(self, node: ast.AST) -> str:
        return ast.unparse(node)


def _pairs(assign: ast.Assign) -> List[Tuple[ast.AST, ast.AST]]:
    """(target, value) of an assignment, a tuple's element by element (a, b = x, y)."""
    out = []
    for t in assign.targets:
        if isinstance(t, ast.Tuple) and isinstance(assign.value, ast.Tuple) and len(
                t.elts) == len(assign.value.elts):
            out += list(zip(t.elts, assign.value.elts))
        else:
            out.append((t, assign.value))
    return out


class Collector:
    """The message templates of a set of modules (module docstring)."""

    def __init__(self, modules: Iterable[Module], producers: Dict[str, Iterable[str]],
                 expansions=None, forwarded=None, composers=None):
        self.modules = list(modules)
        self.producers = producers
        self.composers = COMPOSERS if composers is None else composers
        self.expansions = EXPANSIONS if expansions is None else expansions
        self.forwarded = FORWARDED if forwarded is None else forwarded
        self.constants: Dict[str, Tuple[Module, ast.AST]] = {}
        self.inline: Dict[str, Tuple[Module, ast.AST]] = {}
        for m in self.modules:
            for name, value in m.constants.items():
                self.constants.setdefault(name, (m, value))
            for node in m.tree.body:          # one-line module functions (failsafe)
                if isinstance(node, ast.FunctionDef):
                    body = [s for s in node.body if not (isinstance(s, ast.Expr) and isinstance(
                        s.value, ast.Constant))]
                    if len(body) == 1 and isinstance(body[0], ast.Return):
                        self.inline[node.name] = (m, node)
        self.found: Dict[str, List[Site]] = {}
        self.unexplained: List[str] = []     # all-wildcard sinks not in FORWARDED
        self.forwarded_seen: Set[Tuple[str, str]] = set()

    # --- templates ----------------------------------------------------------------------------
    def texts(self, m: Module, node: Optional[ast.AST], bound=None, depth=0) -> Set[str]:
        """The templates an expression may stand for (W: unknown text); set() for None."""
        if node is None or depth > 12:
            return {W}
        bound = bound or {}
        d = depth + 1
        expansion = self.expansions.get((m.path, m.source(node)))
        if expansion is not None:
            return set(expansion())
        if isinstance(node, ast.Constant):
            if node.value is None:
                return set()
            return {node.value} if isinstance(node.value, str) else {W}
        if isinstance(node, ast.JoinedStr):
            return _product([self.texts(m, v, bound, d) if isinstance(v, ast.Constant) else {W}
                             for v in node.values])
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
            return _product([self.texts(m, node.left, bound, d) or {W},
                             self.texts(m, node.right, bound, d) or {W}])
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mod):
            return self._percent(m, node, bound, d)
        if isinstance(node, ast.IfExp):
            return self.texts(m, node.body, bound, d) | self.texts(m, node.orelse, bound, d)
        if isinstance(node, ast.BoolOp):
            return set().union(*(self.texts(m, v, bound, d) for v in node.values))
        if isinstance(node, ast.Name):
            return self._name(m, node, bound, d)
        if isinstance(node, ast.Attribute):
            if node.attr in self.constants and node.attr.isupper():
                cm, value = self.constants[node.attr]
                return self.texts(cm, value, None, d)
            return {W}
        if isinstance(node, ast.Call):
            return self._call(m, node, bound, d)
        return {W}

    def _percent(self, m, node, bound, d):
        args = node.right.elts if isinstance(node.right, ast.Tuple) else [node.right]
        out = set()
        for fmt in self.texts(m, node.left, bound, d):
            parts, k, pos = [], 0, 0
            for f in _FIELD.finditer(fmt):
                parts.append({fmt[pos:f.start()]})
                pos = f.end()
                if f.group(1) == '%':
                    parts.append({'%'})
                    continue
                arg = args[k] if k < len(args) else None
                k += 1
                if f.group(1) in 'sra' and arg is not None:
                    parts.append(self.texts(m, arg, bound, d) or {W})
                else:
                    parts.append({W})
            parts.append({fmt[pos:]})
            out |= _product(parts)
        return out

    def _name(self, m, node, bound, d):
        if node.id in bound:
            return bound[node.id]
        function = m.parent_function.get(node)
        if function is not None:
            values = [a.value for a in ast.walk(function)
                      if isinstance(a, ast.Assign) and any(
                          isinstance(t, ast.Name) and t.id == node.id for t in a.targets)]
            args = function.args
            params = {a.arg for a in args.posonlyargs + args.args + args.kwonlyargs}
            loops = any(isinstance(f, (ast.For, ast.comprehension)) and any(
                isinstance(t, ast.Name) and t.id == node.id for t in ast.walk(f.target))
                for f in ast.walk(function))
            if values or node.id in params or loops:
                out = set().union(set(), *(self.texts(m, v, None, d) for v in values))
                return out | ({W} if node.id in params or loops or not values else set())
        if node.id in m.constants:
            return self.texts(m, m.constants[node.id], None, d)
        if node.id in self.constants:
            cm, value = self.constants[node.id]
            return self.texts(cm, value, None, d)
        return {W}

    def _call(self, m, node, bound, d):
        f = node.func
        if isinstance(f, ast.Attribute) and f.attr == 'join' and node.args:
            items = node.args[0]                  # a comprehension's (or a local one's) element
            if isinstance(items, ast.Name) and m.parent_function.get(items) is not None:
                items = next((a.value for a in ast.walk(m.parent_function[items])
                              if isinstance(a, ast.Assign) and isinstance(a.value, ast.ListComp)
                              and any(isinstance(t, ast.Name) and t.id == items.id
                                      for t in a.targets)), items)
            if isinstance(items, (ast.GeneratorExp, ast.ListComp)):
                return self.texts(m, items.elt, bound, d)
        if isinstance(f, ast.Attribute) and f.attr == 'format':
            return {_collapse(_BRACES.sub(W, t)) for t in self.texts(m, f.value, bound, d)}
        if isinstance(f, ast.Name) and f.id in self.inline:
            im, fn = self.inline[f.id]
            names = [a.arg for a in fn.args.args]
            call_bound = {n: self.texts(m, a, bound, d) or {W} for n, a in zip(names, node.args)}
            return self.texts(im, fn.body[-1].value, call_bound, d)
        return {W}

    # --- sinks and producers ------------------------------------------------------------------
    def add(self, m: Module, node: ast.AST, kind: str, explained: bool = False) -> bool:
        """The templates of node, made at this site (whether there are any); an all-wildcard
        sink must be FORWARDED.
        """
        texts = {t for t in self.texts(m, node) if re.search(r'[A-Za-z]', t.replace(W, ''))}
        for t in texts:
            t = re.sub(r'\s+', ' ', t).strip()
            self.found.setdefault(t, []).append(Site(m.path, node.lineno, kind))
        if not texts and not explained:
            self._forwarded(m, node, kind)
        return bool(texts)

    def _forwarded(self, m, node, kind):
        site = (m.path, m.source(node))
        if site in self.forwarded:
            self.forwarded_seen.add(site)
        else:
            self.unexplained.append('%s:%d %s: %s' % (m.path, node.lineno, kind, site[1]))

    def _strings(self, m, node, kind, composed=False):
        """A producer's value: a string, or a list, tuple or comprehension of them (whether it
        gave a template). composed: an item a composer adds to its list of messages, which
        must give one or be FORWARDED (a list's elements one by one; a tuple as a whole).
        """
        if isinstance(node, ast.List):
            return any([self._strings(m, e, kind, composed) for e in node.elts])
        if isinstance(node, ast.ListComp):
            return self._strings(m, node.elt, kind, composed)
        if isinstance(node, ast.Tuple):
            found = any([self._strings(m, e, kind) for e in node.elts])
        else:
            found = self.add(m, node, kind, explained=True)
        if composed and not found:
            self._forwarded(m, node, kind)
        return found

    def _logger(self, m, call):
        """Whether call is a log at WARN or above (or an alias of one)."""
        f = call.func
        if isinstance(f, ast.Attribute) and f.attr in LOG_LEVELS and isinstance(
                f.value, ast.Call) and 'get_logger' in m.source(f.value.func):
            return True
        if isinstance(f, ast.Name):
            function = m.parent_function.get(call)
            for a in ast.walk(function) if function is not None else ():
                if isinstance(a, ast.Assign) and any(isinstance(t, ast.Name) and t.id == f.id
                                                     for t in a.targets):
                    return any(isinstance(x, ast.Attribute) and x.attr in LOG_LEVELS
                               and 'get_logger' in m.source(x.value) for x in ast.walk(a.value))
        return False

    def scan_sinks(self, m: Module) -> None:
        for node in ast.walk(m.tree):
            if isinstance(node, ast.Call):
                f = node.func
                name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(
                    f, ast.Attribute) else ''
                if self._logger(m, node) and node.args:
                    self.add(m, node.args[0], 'log')
                elif (name == 'warn' and 'refusals' in m.source(f)
                      and len(node.args) == 2):
                    self.add(m, ast.BinOp(node.args[0], ast.Add(), node.args[1],
                                          lineno=node.lineno), 'log')
                elif m.source(f) == 'sys.stderr.write' and node.args:
                    self.add(m, node.args[0], 'log')
                elif name == 'print' and node.args:          # a command's output
                    self.add(m, node.args[0], 'output')
                elif name == '_text' and node.args:
                    self.add(m, node.args[0], 'statustext')
                elif name in STATUS_CLASSES and len(node.args) > STATUS_CLASSES[name]:
                    self.add(m, node.args[STATUS_CLASSES[name]], name)
                elif name == 'DiagnosticStatus':
                    for k in node.keywords:
                        if k.arg == 'message':
                            self.add(m, k.value, 'diagnostics')
                elif name == 'failsafe' and node.args:
                    self.add(m, node.args[0], 'failsafe')
                elif name in EXCEPTIONS and node.args:
                    self.add(m, node.args[0], name)
                elif name == 'ConfigError' and node.args:
                    pairs = node.args[0]
                    if isinstance(pairs, ast.List) and all(
                            isinstance(p, ast.Tuple) and len(p.elts) == 2 for p in pairs.elts):
                        for p in pairs.elts:
                            self.add(m, p.elts[1], 'ConfigError', explained=True)
                        if not any(self.texts(m, p.elts[1]) - {W} for p in pairs.elts):
                            self._forwarded(m, pairs, 'ConfigError')
            elif isinstance(node, ast.Assign):
                for target, value in _pairs(node):
                    if (isinstance(target, ast.Attribute) and target.attr == 'message'
                            and m.source(target.value) == 'response'):
                        self.add(m, value, 'reply')

    def scan_producer(self, m: Module, qualname: str) -> None:
        function = m.functions[qualname]
        kind = 'producer ' + qualname
        composer = (m.path, qualname) in self.composers
        args = function.args
        for a, default in zip(reversed(args.args), reversed(args.defaults)):
            if a.arg == 'reason':
                self._strings(m, default, kind)
        for node in ast.walk(function):
            if isinstance(node, ast.Return) and node.value is not None:
                self._strings(m, node.value, kind)
            elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                if m.source(node.func) == 'super().__init__' and node.args:   # an exception's
                    self._strings(m, node.args[0], kind)
                elif node.func.attr == 'append' and node.args:
                    self._strings(m, node.args[0], kind, composer)
                elif node.func.attr == 'insert' and len(node.args) == 2:
                    self._strings(m, node.args[1], kind, composer)
            elif isinstance(node, ast.AugAssign) and isinstance(node.op, ast.Add):
                if composer or isinstance(node.value, (ast.List, ast.ListComp)):
                    self._strings(m, node.value, kind, composer)
            elif isinstance(node, ast.Assign):
                for target, value in _pairs(node):
                    name = (target.id if isinstance(target, ast.Name) else target.attr
                            if isinstance(target, ast.Attribute) else None)
                    if name in MESSAGE_NAMES:
                        self._strings(m, value, kind)
                    elif composer and isinstance(value, (ast.List, ast.ListComp)):
                        self._strings(m, value, kind, composer)

    def collect(self) -> Dict[str, List[Site]]:
        for m in self.modules:
            self.scan_sinks(m)
            for qualname in self.producers.get(m.path, ()):
                self.scan_producer(m, qualname)
        return self.found

    @property
    def stale_forwarded(self) -> List[Tuple[str, str]]:
        """FORWARDED entries of the scanned files that name no sink any more."""
        paths = {m.path for m in self.modules}
        return sorted(k for k in self.forwarded if k[0] in paths and k not in self.forwarded_seen)


def package_path(path: str) -> str:
    return os.path.join(PKG, path)


def package_modules() -> List[Module]:
    paths = sorted({p for paths in SOURCES.values() for p in paths})
    return [Module(p, open(package_path(p)).read()) for p in paths]


def collect(modules: Optional[List[Module]] = None, producers=None) -> Collector:
    """The collector, run over modules (default: SOURCES's) with producers (default: PRODUCERS)."""
    c = Collector(package_modules() if modules is None else modules,
                  PRODUCERS if producers is None else producers)
    c.collect()
    return c


# --- docs/operator.md ----------------------------------------------------------------------------
class Row(NamedTuple):
    """A table row of the reference: its first cell's code spans (as templates), whether it has
    an action (and a level, where its table has that column), its table's first header, its
    level (empty without that column) and its line.
    """

    spans: Tuple[str, ...]
    complete: bool
    first_header: str
    level: str
    line: int


def _cells(line: str) -> List[str]:
    return [c.strip().replace('\\|', '|')
            for c in re.split(r'(?<!\\)\|', line.strip().strip('|'))]


def rows(text: str) -> List[Row]:
    """The rows of every table that has a "what to do" column."""
    out, header = [], None
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if not line.startswith('|'):
            header = None
            continue
        cells = _cells(line)
        if header is None:
            header = [c.lower() for c in cells]
            continue
        if set(''.join(cells)) <= set('-: '):
            continue
        action = next((k for k, h in enumerate(header) if h.startswith('what to do')), None)
        if action is None:
            continue
        level = header.index('level') if 'level' in header else None
        complete = all(k < len(cells) and cells[k] for k in (action, level) if k is not None)
        spans = tuple(_collapse(re.sub(r'\s+', ' ', s).strip().replace('...', W))
                      for s in re.findall(r'`([^`]+)`', cells[0]))
        out.append(Row(spans, complete, header[0],
                       cells[level] if level is not None and level < len(cells) else '', i + 1))
    return out


def _glob_prefix(t: str) -> str:
    return t.split(W, 1)[0]


def compatible(a: str, b: str) -> bool:
    """Whether some text matches both templates (W in either: any text, empty too)."""
    pa, pb = _glob_prefix(a), _glob_prefix(b)
    n = min(len(pa), len(pb))
    if pa[:n] != pb[:n]:
        return False
    sa, sb = a.rsplit(W, 1)[-1], b.rsplit(W, 1)[-1]
    n = min(len(sa), len(sb))
    if n and sa[-n:] != sb[-n:]:
        return False
    seen, todo = {(0, 0)}, deque([(0, 0)])
    while todo:
        i, j = todo.popleft()
        if i == len(a) and j == len(b):
            return True
        nxt = []
        if i < len(a) and a[i] == W:
            nxt.append((i + 1, j))
            if j < len(b):
                nxt.append((i, j + 1))
        if j < len(b) and b[j] == W:
            nxt.append((i, j + 1))
            if i < len(a):
                nxt.append((i + 1, j))
        if i < len(a) and j < len(b) and a[i] == b[j] != W:
            nxt.append((i + 1, j + 1))
        for s in nxt:
            if s not in seen:
                seen.add(s)
                todo.append(s)
    return False


def shows(span: str, template: str) -> bool:
    """Whether a row's span shows the template: some text matches both, and, when the
    template begins with a field, its first words stand in the span as written, not inside one
    of its ``...`` (else a span that ends in ``...`` would show every template that begins with a
    field: ``... refused: ...``). (A span that begins with ``...`` does not count: ``missing``.)
    """
    if template.startswith(W):
        first = next(part for part in template.split(W) if re.search('[A-Za-z]', part))
        if not any(first.strip() in part for part in span.split(W)):
            return False
    return compatible(template, span)


def shown(template: str) -> str:
    """A template as the reference would show it (``...`` for each wildcard)."""
    return template.replace(W, '...')


def missing(templates: Iterable[str], reference: List[Row], keys: bool = False) -> List[str]:
    """The templates no complete row of the reference shows (in the key tables, for keys). A
    span that begins with ``...`` does not count: it would match any template that ends in a
    field.
    """
    spans = [s for r in reference if r.complete and (r.first_header == 'key') == keys
             for s in r.spans if s.replace(W, '').strip() and not s.startswith(W)]
    return sorted(t for t in templates if not any(shows(s, t) for s in spans))


def unknown_spans(templates: Iterable[str], keys: Iterable[str],
                  reference: List[Row]) -> List[str]:
    """The spans of the reference's rows that show no template of the code (a message renamed
    or gone), but for the rows at INFO (the start-up lines, which the collector does not read).
    """
    templates, keys = list(templates), list(keys)
    return ['line %d: %s' % (r.line, shown(s)) for r in reference if r.level != 'INFO'
            for s in r.spans
            if not any(shows(s, t) for t in (keys if r.first_header == 'key' else templates))]


def diagnostics_keys() -> List[str]:
    """Every key the three nodes' diagnostics codecs define, as templates: an expanded field's
    keys are its prefix and each entry the code names (``entries``, the link's and the
    verifier's counters), or the prefix and a wildcard (the ESCs, numbered).
    """
    from geoctl_ros.core.telemetry import diagnostics  # noqa: PLC0415
    from geoctl_ros.esc import health as esc_health  # noqa: PLC0415
    from geoctl_ros.mavlink import health as bridge_health  # noqa: PLC0415
    counters = {'link_counts': _dict_keys('mavlink/link.py', 'counts'),
                'refused': _dict_keys('mavlink/signing.py', 'refused')}
    out = []
    for codec in (diagnostics.CODEC, esc_health.CODEC, bridge_health.CODEC):
        for field, k in codec.table.items():
            if not k.expand:
                out.append(k.key)
            elif k.entries is not None:
                out += [k.key + e for e in k.entries]
            elif field in counters and not k.numbered:
                out += [k.key + e for e in counters[field]]
            else:
                out.append(k.key + W)
    return out


def _dict_keys(path: str, attribute: str) -> List[str]:
    """The keys of the dict literal assigned to self.<attribute> in a package file."""
    tree = ast.parse(open(os.path.join(PKG, path)).read())
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Dict) and any(
                isinstance(t, ast.Attribute) and t.attr == attribute for t in node.targets):
            return [k.value for k in node.value.keys]
    raise AssertionError('no dict self.%s in %s' % (attribute, path))
