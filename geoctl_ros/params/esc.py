"""The ESC node's set-up and the sim's virtual ESC bus, typed, from resolved parameters."""
from dataclasses import dataclass
from typing import Optional, Tuple

from geoctl_ros.params.param import MOTOR_TEST_COMMAND_MAX


@dataclass(frozen=True)
class EscConfig:
    """What the ESC driver (``geoctl_ros.esc.driver``) decides with."""

    addresses: tuple                  # 7-bit address per rotor, in rotor order
    command_max: int                  # the set point of a normalised command of 1 (one byte)
    resolution: int = 8               # 8: one byte per write; 11: two
    timeout: float = 0.1              # s: older commands give zero
    ignore: frozenset = frozenset()   # rotors (1-based) whose ESC may be missing
    retries: int = 2                  # retries of a failed write within a cycle
    probe_timeout: float = 3.0        # s: how long start-up waits for every ESC to answer
    test_command_max: float = MOTOR_TEST_COMMAND_MAX      # the largest motor-test command


@dataclass(frozen=True)
class MotorTest:
    """The motor test the node's ``~/motor_test`` service starts."""

    rotor: int            # 1-based
    command: float        # normalised
    duration: float       # s


@dataclass(frozen=True)
class EscSetup:
    """The ESC node's set-up."""

    driver: EscConfig
    bus: int                          # /dev/i2c-<bus>
    virtual_bus: str                  # a virtual bus file instead ('' : the real bus)
    rate_hz: float                    # least write rate
    telemetry_rate_hz: float          # ESC reads per second
    temperature_warn: float           # deg C
    temperature_error: float          # deg C
    controller: str                   # the controller node followed
    motor_test: MotorTest


def esc_config(values: dict) -> EscConfig:
    """The EscConfig of resolved esc_i2c parameters."""
    return EscConfig(addresses=tuple(int(a) for a in values['esc.addresses']),
                     command_max=int(values['motor.command_max']),
                     resolution=int(values['esc.resolution']), timeout=values['esc.timeout'],
                     ignore=frozenset(int(r) for r in values['esc.ignore']),
                     retries=int(values['esc.retries']),
                     probe_timeout=values['esc.probe_timeout'])


def esc_setup(values: dict) -> EscSetup:
    """The EscSetup of resolved esc_i2c parameters."""
    return EscSetup(esc_config(values), int(values['esc.bus']), values['esc.virtual_bus'],
                    values['esc.rate_hz'], values['esc.telemetry_rate_hz'],
                    values['esc.temperature_warn'], values['esc.temperature_error'],
                    values['esc.controller'],
                    MotorTest(int(values['motor_test.rotor']), values['motor_test.command'],
                              values['motor_test.duration']))


@dataclass(frozen=True)
class VirtualEscs:
    """The sim's ESCs on a virtual I2C bus: its file and their addresses, in rotor order."""

    path: str
    addresses: Tuple[int, ...]


def virtual_escs(values: dict) -> Optional[VirtualEscs]:
    """The VirtualEscs of resolved sim parameters, or None (the sim takes motor_commands)."""
    if not values['esc.virtual_bus']:
        return None
    return VirtualEscs(values['esc.virtual_bus'], tuple(int(a) for a in values['esc.addresses']))
