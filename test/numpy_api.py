"""The names numpy 1.26 has, and a scan of source files for numpy names it lacks.

Ubuntu 24.04, the vehicle's stack, ships numpy 1.26.4 (python3-numpy); the development stack has
numpy 2.x, where code can reach for ``ndarray.mT`` or ``np.matvec`` without noticing. The list of
numpy 1.26's names is committed (``test/data/numpy-1.26.txt``) so that the check runs on either
stack; on numpy 1.26 itself the test also checks that the list is still what numpy has.

    python test/numpy_api.py > test/data/numpy-1.26.txt     # with numpy 1.26 installed
"""
import ast
import sys

import numpy as np
import numpy.typing  # noqa: F401  (imported by core/'s annotations: listed whatever was imported)

# the submodules whose names are listed (what ``np.<sub>.<name>`` can reach)
SUBMODULES = ('char', 'ctypeslib', 'dtypes', 'emath', 'exceptions', 'fft', 'lib', 'linalg', 'ma',
              'polynomial', 'random', 'rec', 'testing', 'typing')


def names():
    """numpy.<name>, numpy.<sub>.<name> and ndarray.<attribute> of the numpy installed."""
    out = {'numpy.' + n for n in dir(np)}
    for sub in SUBMODULES:
        module = getattr(np, sub, None)
        if module is not None:
            out |= {'numpy.%s.%s' % (sub, n) for n in dir(module)}
    out |= {'ndarray.' + n for n in dir(np.ndarray)}
    return sorted(out)


def missing(source, have, new_attributes):
    """(line, name) for each numpy name in source (Python text) that `have` lacks.

    Names reached through an alias of numpy or of a listed submodule (``import numpy as np``,
    ``from numpy import linalg``) are checked in full; an attribute of any other object is
    checked against new_attributes, the ndarray attributes newer numpy has and `have` lacks (an
    array's type is not known from the text, so ``x.mT`` counts whatever x is).
    """
    tree = ast.parse(source)
    aliases = {}
    found = []
    modules = {'numpy'} | {n.rsplit('.', 1)[0] for n in have if n.count('.') == 2}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split('.')[0] == 'numpy':
                    aliases[a.asname or a.name.split('.')[0]] = a.name if a.asname else 'numpy'
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0 and (
                node.module.split('.')[0] == 'numpy'):
            for a in node.names:
                full = '%s.%s' % (node.module, a.name)
                if node.module in modules and full not in have:
                    found.append((node.lineno, full))
                aliases[a.asname or a.name] = full
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        chain, base = [node.attr], node.value
        while isinstance(base, ast.Attribute):
            chain.append(base.attr)
            base = base.value
        if isinstance(base, ast.Name) and base.id in aliases:
            full = aliases[base.id]
            for part in reversed(chain):        # np.linalg.norm: numpy.linalg, then its norm
                if full not in modules:
                    break                       # an attribute of a function or class
                full += '.' + part
                if full not in have:
                    found.append((node.lineno, full))
                    break
        elif node.attr in new_attributes:
            found.append((node.lineno, 'ndarray.' + node.attr))
    return sorted(set(found))                   # np.a.b is also seen as its inner np.a


if __name__ == '__main__':
    sys.stdout.write('# numpy %s: dir(numpy), dir(numpy.<sub>), dir(numpy.ndarray)\n'
                     % np.__version__)
    sys.stdout.write(''.join(n + '\n' for n in names()))
