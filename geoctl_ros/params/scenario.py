"""A scenario's parameters, resolved: what ``geoctl_ros.sim.scenario.load`` returns and the closed
loop flies (``geoctl_ros.sim.closed_loop``).
"""
from dataclasses import dataclass


@dataclass
class Scenario:
    """A loaded, validated scenario."""

    name: str
    controller: dict   # resolved controller parameters
    sim: dict          # resolved sim parameters
    options: dict      # resolved scenario parameters (duration, title)
