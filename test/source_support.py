"""What the tests that read the source share (test_layers, test_package): where the tree and
the package are, and what a source file imports.
"""
import ast
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PKG = os.path.join(ROOT, 'geoctl_ros')


def imported_modules(path):
    """The modules a source file imports (every import statement, anywhere in it)."""
    tree = ast.parse(open(path).read())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            yield node.module
        elif isinstance(node, ast.Import):
            for a in node.names:
                yield a.name


def module_level_imports(path, functions=False):
    """The modules a source file imports when it is imported: every import statement but those
    inside a function (a class body or an ``if``/``try`` at the top runs on import too); with
    functions, those too. A name imported from a module is given as that module's too (``from a
    import b``: ``a`` and ``a.b``, which may be a module).
    """
    def walk(node):
        for child in ast.iter_child_nodes(node):
            if not functions and isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                    ast.Lambda)):
                continue
            if isinstance(child, ast.ImportFrom) and child.module:
                yield child.module
                yield from ('%s.%s' % (child.module, a.name) for a in child.names)
            elif isinstance(child, ast.Import):
                yield from (a.name for a in child.names)
            yield from walk(child)
    yield from walk(ast.parse(open(path).read()))


def package_modules():
    """{dotted name: path} of every module of the package (a package by its __init__)."""
    files = {}
    for dirpath, _, names in os.walk(PKG):
        for f in names:
            if f.endswith('.py'):
                rel = os.path.relpath(os.path.join(dirpath, f), ROOT)[:-3].split(os.sep)
                if rel[-1] == '__init__':
                    rel = rel[:-1]
                files['.'.join(rel)] = os.path.join(dirpath, f)
    return files
