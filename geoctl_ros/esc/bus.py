"""The I2C buses an ESC driver writes: Linux i2c-dev (smbus2's I2C_RDWR, plain I2C messages with
no register byte, as the BL-Ctrl expects), and a recording bus for the tests.

Every bus has ``write(address, data)`` and ``read(address, n)``, and raises ``BusError`` (with the
address and a kind: 'nack', 'timeout' or 'io') when a transfer fails.
"""
from collections import deque
import errno
import threading
import time
from typing import Optional

from smbus2 import SMBus, i2c_msg

NACK_ERRNOS = (errno.ENXIO, errno.EREMOTEIO, errno.EIO)   # what i2c-dev drivers give for a NACK
TIMEOUT_ERRNOS = (errno.ETIMEDOUT, errno.EAGAIN)


class BusError(OSError):
    """A failed transfer: kind is 'nack' (nobody answered the address), 'timeout' or 'io'."""

    def __init__(self, address, kind, detail=''):
        super().__init__('I2C %s at 0x%02x%s' % (kind, address, ': ' + detail if detail else ''))
        self.address, self.kind = address, kind


class I2cBus:
    """/dev/i2c-N through smbus2 (OSError from the constructor: no such bus, or no permission)."""

    def __init__(self, number):
        self.name = '/dev/i2c-%d' % number
        self._bus = SMBus(number)

    def _transfer(self, address, msg):
        try:
            self._bus.i2c_rdwr(msg)
        except OSError as e:
            kind = ('nack' if e.errno in NACK_ERRNOS else
                    'timeout' if e.errno in TIMEOUT_ERRNOS else 'io')
            raise BusError(address, kind, e.strerror or str(e)) from None

    def write(self, address: int, data: bytes) -> None:
        self._transfer(address, i2c_msg.write(address, bytes(data)))

    def read(self, address: int, n: int) -> bytes:
        msg = i2c_msg.read(address, n)
        self._transfer(address, msg)
        return bytes(msg)

    def close(self) -> None:
        self._bus.close()


class RecordingBus:
    """A bus for the tests: records every write that went through (time, address, bytes), answers
    reads with each ESC's telemetry, and fails on demand.

    present: the addresses that answer (the others NACK). fail(address, kind, count): the next
    count transfers to it fail with kind ('nack' or 'timeout'). stuck: addresses whose every
    transfer times out after ``stuck_delay`` seconds (an ESC holding the clock line).
    """

    def __init__(self, present=(), clock=time.monotonic, history=100_000):
        self.name = 'recording bus'
        self.present = set(present)
        self.stuck = set()
        self.stuck_delay = 0.0
        self.telemetry = {a: bytes((0, 250, 25)) for a in self.present}   # 0 A, V2 ready, 25 C
        self.writes = deque(maxlen=history)
        self.errors = []
        self._faults = {}
        self._clock = clock
        self._lock = threading.Lock()

    def fail(self, address: int, kind: str = 'nack', count: int = 1) -> None:
        with self._lock:
            self._faults.setdefault(address, deque()).extend([kind] * count)

    def _check(self, address):
        if address in self.stuck:
            if self.stuck_delay:
                time.sleep(self.stuck_delay)
            raise BusError(address, 'timeout')
        with self._lock:
            queued = self._faults.get(address)
            kind = queued.popleft() if queued else None
        if kind is None and address not in self.present:
            kind = 'nack'
        if kind is not None:
            self.errors.append((self._clock(), address, kind))
            raise BusError(address, kind)

    def write(self, address: int, data: bytes) -> None:
        self._check(address)
        self.writes.append((self._clock(), address, bytes(data)))

    def read(self, address: int, n: int) -> bytes:
        self._check(address)
        return self.telemetry[address][:n]

    def last(self, address: int) -> Optional[bytes]:
        """The last bytes written to address, or None."""
        for _, a, data in reversed(self.writes):
            if a == address:
                return data
        return None

    def close(self) -> None:
        pass
