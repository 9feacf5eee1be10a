"""What the tests of the development tools share: why they are skipped where setup.py's extra
``tools`` is not installed (the vehicle's stack, as the vehicle: docs/stacks.md).
"""
NO_EXTRA = 'a development tool: needs the extra tools, which the vehicle stack has not'
