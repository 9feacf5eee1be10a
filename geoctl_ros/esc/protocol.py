"""The BL-Ctrl I2C protocol (MikroKopter's description; BL-Ctrl 2.0 and 3.0 alike).

A write to an ESC's 7-bit address carries its set point: one byte (0-255), or 11 bits as two bytes,
sp / 8 then sp % 8 (only the low 3 bits of the second are used). This package's commands are
normalised (command / ``motor.command_max``, as the controller publishes them): one byte is
round(c * command_max), the lab's 0..240; 11 bits are round(c * command_max * 8), the same throttle
with three more bits (``esc.resolution``).

A read returns current, a state byte and temperature (BL-Ctrl 2.0: three bytes):

- current: up to 200 in 0.1 A, above that 1 A steps from 20 A (201 = 21 A), 255 not valid;
- state: 255 running, 254 running redundant, 250 V2 ready, 248-249 V3 ready, 50-247 running but
  limited by temperature or current, 40 starting, 39 start failed, 1-20 self-test error (some
  sources call it MaxPWM);
- temperature in deg C.
"""
from dataclasses import dataclass
import math
from typing import List, Tuple

import numpy as np

TELEMETRY_BYTES = 3
OK, WARN, ERROR = 0, 1, 2                 # diagnostic_msgs levels, without rclpy


def encode(commands: np.ndarray, command_max: int, resolution: int = 8) -> List[bytes]:
    """The bytes to write to each ESC for normalised commands in [0, 1]: a list of bytes objects,
    one per rotor.
    """
    c = np.clip(np.asarray(commands, dtype=float), 0.0, 1.0)
    if resolution == 8:
        return [bytes((v,)) for v in np.minimum(np.rint(c * command_max), 255).astype(int)]
    sp = np.minimum(np.rint(c * command_max * 8), 2047).astype(int)
    return [bytes((v >> 3, v & 7)) for v in sp]


def decode(data: bytes, command_max: int) -> float:
    """The normalised command of the bytes written to one ESC (one byte, or two for 11 bits)."""
    if len(data) == 1:
        return data[0] / command_max
    return ((data[0] << 3) | (data[1] & 7)) / (8.0 * command_max)


def current_amps(raw: int) -> float:
    """Current of the read's first byte, A (NaN for 255, not valid)."""
    if raw == 255:
        return math.nan
    return raw / 10.0 if raw <= 200 else float(raw - 180)


def current_raw(amps: float) -> int:
    """The first byte of a read for a current (what an ESC sends; the virtual ESCs use it)."""
    if not amps >= 0.0:
        return 255
    return int(round(amps * 10.0)) if amps <= 20.0 else min(254, int(round(amps)) + 180)


@dataclass(frozen=True)
class Telemetry:
    """One ESC's read: current (A, NaN if not valid), state byte, temperature (deg C)."""

    current: float
    state: int
    temperature: float


def parse(data: bytes) -> 'Telemetry':
    """Telemetry of a read's bytes (ValueError if too short)."""
    if len(data) < TELEMETRY_BYTES:
        raise ValueError('an ESC read returned %d bytes, expected %d' % (len(data),
                                                                        TELEMETRY_BYTES))
    return Telemetry(current_amps(data[0]), int(data[1]), float(data[2]))


def state_problem(state: int) -> Tuple[int, str]:
    """(level, what) of a state byte: OK for running and ready, WARN for limiting or unknown,
    ERROR for a failed start or a self-test error.
    """
    if state in (255, 254):
        return OK, 'running'
    if state in (248, 249, 250):
        return OK, 'ready'
    if state == 40:
        return OK, 'starting'
    if 50 <= state <= 247:
        return WARN, 'limited by temperature or current (state %d)' % state
    if state == 39:
        return ERROR, 'start failed'
    if 1 <= state <= 20:
        return ERROR, 'self-test error %d' % state
    return WARN, 'unknown state %d' % state
