"""What a batch of runs is made of (``geoctl_ros.sim.closed_loop``): what may differ between its
runs, the controller and testbeds built from their scenarios, the noise each run draws from its
own seed, the late steps and the stalls.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Callable, Iterator, Tuple

import numpy as np

from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.control import AttitudeController
from geoctl_ros.params import controller_setup
from geoctl_ros.params.testbed import Disturbance, PlantConfig, TestbedSetup
from geoctl_ros.sim.plant import Plant
from geoctl_ros.sim.testbed import rotor_actuator


def hold_steps(steps: int, n_sub: int, jitter: float, seed: int) -> np.ndarray:
    """How many integration steps each control step's command is held, for a run of ``steps``
    periods of n_sub integration steps: n_sub each, or with jitter (in integration steps, > 0)
    n_sub plus a uniform random whole number in 0..jitter, as on a machine too busy to run the
    loop on time: the steps come late, one after the other, and fewer fit in the run. From a
    stream of its own of ``seed``, so the noise is the same with and without it.
    """
    if jitter <= 0.0:
        return np.full(steps, n_sub)
    holds = n_sub + np.random.default_rng([seed, 1]).integers(0, int(round(jitter)) + 1, steps)
    starts = np.cumsum(holds) - holds
    return holds[starts < steps * n_sub]


def late_holds(n_sub: int, jitter: float, seed: int, stream: int) -> Iterator[int]:
    """An endless draw of holds (integration steps) as ``hold_steps``' (n_sub, late by up to
    jitter), from the stream of its own of ``seed``: the spool-up's ticks before a take-over.
    """
    rng = np.random.default_rng([seed, stream])
    while True:
        yield n_sub + (int(rng.integers(0, int(round(jitter)) + 1)) if jitter > 0.0 else 0)


def shared_holds(bed: 'Testbeds', rate: float, n_sub: int, duration: float) -> np.ndarray:
    """The batch's hold sequence (integration steps per control step): the runs must share it."""
    h = 1.0 / (rate * n_sub)
    steps = int(round(duration * rate))
    holds = [hold_steps(steps, n_sub, o.tick_jitter / h,
                        b.noise.seed if o.tick_jitter_seed < 0 else o.tick_jitter_seed)
             for o, b in zip(bed.options, bed.beds)]
    if any(not np.array_equal(holds[0], x) for x in holds[1:]):
        raise ValueError('the runs of a batch share their late steps: with scenario.tick_jitter '
                         'they fly together only with the same tick_jitter_seed (or noise.seed)')
    return holds[0]


class Testbeds:
    """The controller and the simulated testbeds of a batch, built from its scenarios."""

    def __init__(self, scenarios):
        cv = scenarios[0].controller
        n = len(scenarios)
        self.setup = setup = controller_setup(cv)                     # gains, model, mixer

        # each run's testbed, as the sim node builds its own (params.testbed.testbed_setup)
        self.beds = beds = [s.testbed for s in scenarios]
        self.options = [s.options for s in scenarios]

        # One run flies its testbed unstacked: its small products then go in floats, in the order
        # of a stack's (geoctl_ros.core.geometry.so3), the same bits three times faster.
        def per_run(get: Callable[[TestbedSetup], Any]) -> np.ndarray:
            stacked = np.array([get(b) for b in beds], dtype=float)
            return stacked[0] if n == 1 else stacked
        self.single = n == 1

        shared = setup.config.cones
        sets = [s.cones() for s in scenarios]
        names = shared.names
        self.cones = ConeSet(shared.r, np.array([c.V for c in sets]).reshape(n, len(names), 3),
                             np.array([c.theta for c in sets]).reshape(n, len(names)),
                             shared.alpha, shared.floor, names, shared.guard)
        self.controller = AttitudeController(replace(setup.config, cones=self.cones))
        self.controller.R_d = np.array([s.setpoint() for s in scenarios])
        self.controller.delta_bar = np.zeros((n, setup.config.n_params))
        first = beds[0].plant        # (what the runs share: checked by ``differing``)
        rho = per_run(lambda b: b.plant.cog_offset)
        self.plant = Plant(
            PlantConfig(inertia=per_run(lambda b: b.plant.inertia), mass=per_run(
                lambda b: b.plant.mass), cog_offset=rho, gravity=first.gravity,
                disturbance=Disturbance(per_run(lambda b: b.plant.disturbance.constant),
                                        first.disturbance.amplitude,
                                        first.disturbance.frequency),
                tilt_max=first.tilt_max),
            np.array([b.R0 for b in beds]).reshape((3, 3) if n == 1 else (n, 3, 3)),
            per_run(lambda b: b.Omega0))
        self.actuator = rotor_actuator(beds[0], rho)           # None with torque: the moment acts
        self.gyro_bias = np.array([b.noise.bias for b in beds])

    def noise(self, steps: int) -> np.ndarray:
        """Per run, the sensors' errors of ``steps`` control steps, (2, steps, runs, 3): each
        run's own (``SensorNoise.drawn``, from its seed).
        """
        out = np.zeros((2, steps, len(self.beds), 3))
        for j, b in enumerate(self.beds):
            out[:, :, j] = b.noise.drawn(steps)
        return out

    def state(self) -> Tuple[np.ndarray, np.ndarray]:
        """The testbeds' attitudes and rates, stacked (runs, ...) also for one run (views)."""
        p = self.plant
        return (p.R[None], p.Omega[None]) if self.single else (p.R, p.Omega)

    def moment(self, command: np.ndarray, h: float) -> np.ndarray:
        """The moment on the testbeds over the next h with the batch's command held: through
        the rotors (integer commands) or, with torque actuation, the commanded moment itself.
        """
        if self.single:
            command = command[0]
        return command if self.actuator is None else self.actuator.moment(command, h)

