"""Telemetry: the typed diagnostics and their keys (one codec), the reporting window's statistics,
and the live view's geometry.
"""
