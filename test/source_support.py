"""What the tests that read the source share (test_layers, test_package)."""
import ast


def imported_modules(path):
    """The modules a source file imports (every import statement, anywhere in it)."""
    tree = ast.parse(open(path).read())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            yield node.module
        elif isinstance(node, ast.Import):
            for a in node.names:
                yield a.name
