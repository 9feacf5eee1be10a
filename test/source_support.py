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
