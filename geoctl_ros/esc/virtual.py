"""A virtual ESC bus in shared memory (a file, normally under /dev/shm), between the ESC node and
the sim: ``esc.virtual_bus`` names it for both.

The ESC node writes it exactly as it writes /dev/i2c-N (``write``/``read``: the encoded set-point
bytes, the telemetry bytes), so a sim-in-the-loop flight goes through the real encoding and the
node's own watchdog; the sim is the six ESCs: it marks them present while it runs, reads each
one's latest bytes and their time, and answers the telemetry. Every write is also kept in a ring
(time, address, bytes) that a test reads afterwards: what the motors were told, and when.

Layout: a header, one slot per ESC address and the ring, as numpy structured arrays over an mmap.
The ESC node is the only writer of set points and of the ring, the sim the only writer of
presence and telemetry; a slot's set point is read under a sequence lock (an odd count while it is
being written). Times are CLOCK_MONOTONIC (``time.monotonic``), which all processes share.
"""
import mmap
import os
import tempfile
import time
from typing import List, Tuple

import numpy as np

from geoctl_ros.esc.bus import BusError

MAGIC = 0x47455343              # 'GESC'
LOG_SIZE = 65536
HEADER = np.dtype([('magic', '<u4'), ('slots', '<u4'), ('log_size', '<u4'), ('pad', '<u4'),
                   ('log_next', '<u8')])
SLOT = np.dtype([('address', 'u1'), ('present', 'u1'), ('nbytes', 'u1'), ('b0', 'u1'),
                 ('b1', 'u1'), ('current', 'u1'), ('state', 'u1'), ('temperature', 'u1'),
                 ('seq', '<u8'), ('t_write', '<f8')])
ENTRY = np.dtype([('t', '<f8'), ('address', 'u1'), ('nbytes', 'u1'), ('b0', 'u1'), ('b1', 'u1'),
                  ('pad', 'u1', 4)])


def _size(slots):
    return HEADER.itemsize + slots * SLOT.itemsize + LOG_SIZE * ENTRY.itemsize


class VirtualEscBus:
    """The bus at path for these ESC addresses (made if missing; an existing one must have as
    many slots).
    """

    def __init__(self, path, addresses):
        self.name = 'virtual ESC bus %s' % path
        self.path = path
        n = len(addresses)
        if not os.path.exists(path):
            fd, tmp = tempfile.mkstemp(dir=os.path.dirname(os.path.abspath(path)) or '.')
            with os.fdopen(fd, 'wb') as f:
                f.truncate(_size(n))
            self._map(tmp, n)
            self.header['magic'], self.header['slots'] = MAGIC, n
            self.header['log_size'] = LOG_SIZE
            self.slots['address'] = addresses
            self.slots['state'], self.slots['temperature'] = 250, 25
            self._mm.flush()
            try:
                os.link(tmp, path)           # atomic: whoever comes second attaches to this one
            except FileExistsError:
                pass
            os.unlink(tmp)
            self._mm.close()
        self._map(path, n)
        if int(self.header['magic']) != MAGIC or int(self.header['slots']) != n:
            raise ValueError('%s is not a virtual ESC bus of %d ESCs' % (path, n))
        self.index = {int(a): i for i, a in enumerate(self.slots['address'])}
        if set(self.index) != {int(a) for a in addresses}:
            raise ValueError('%s has the ESC addresses %s, not %s' % (
                path, sorted(self.index), sorted(addresses)))

    def _map(self, path, n):
        with open(path, 'r+b') as f:
            if os.fstat(f.fileno()).st_size < _size(n):
                raise ValueError('%s is not a virtual ESC bus of %d ESCs' % (path, n))
            self._mm = mmap.mmap(f.fileno(), _size(n))
        self.header = np.ndarray((), HEADER, self._mm, 0)
        self.slots = np.ndarray((n,), SLOT, self._mm, HEADER.itemsize)
        self.ring = np.ndarray((LOG_SIZE,), ENTRY, self._mm, HEADER.itemsize + n * SLOT.itemsize)

    def _slot(self, address):
        i = self.index.get(address)
        if i is None or not self.slots['present'][i]:
            raise BusError(address, 'nack')
        return i

    # --- the ESC node's side (the bus master) -----------------------------------------------
    def write(self, address: int, data: bytes) -> None:
        i = self._slot(address)
        data = bytes(data)
        now = time.monotonic()
        slot = self.slots[i:i + 1]
        slot['seq'] += 1                                   # odd: being written
        slot['nbytes'], slot['b0'] = len(data), data[0]
        slot['b1'] = data[1] if len(data) > 1 else 0
        slot['t_write'] = now
        slot['seq'] += 1
        k = int(self.header['log_next'])
        e = self.ring[k % LOG_SIZE:k % LOG_SIZE + 1]
        e['t'], e['address'], e['nbytes'], e['b0'] = now, address, len(data), data[0]
        e['b1'] = data[1] if len(data) > 1 else 0
        self.header['log_next'] = k + 1

    def read(self, address: int, n: int) -> bytes:
        i = self._slot(address)
        s = self.slots[i]
        return bytes((int(s['current']), int(s['state']), int(s['temperature'])))[:n]

    def close(self) -> None:
        self._mm.close()

    # --- the ESCs' side (the sim) -----------------------------------------------------------
    def power(self, on: bool) -> None:
        """The ESCs answer (on) or not."""
        self.slots['present'] = 1 if on else 0

    def setpoints(self) -> List[Tuple[bytes, float]]:
        """[(bytes written last, its time)] per slot (b'' and -inf before the first write)."""
        out = []
        for i in range(len(self.slots)):
            while True:
                s = self.slots[i].copy()
                if s['seq'] % 2 == 0 and s['seq'] == self.slots['seq'][i]:
                    break
            data = bytes((int(s['b0']), int(s['b1'])))[:int(s['nbytes'])]
            out.append((data, float(s['t_write']) if s['nbytes'] else -np.inf))
        return out

    def answer(self, i: int, current_raw: int, state: int, temperature: int) -> None:
        """Slot i's telemetry (the bytes its next read returns)."""
        self.slots['current'][i], self.slots['state'][i] = current_raw, state
        self.slots['temperature'][i] = int(min(255, max(0, round(temperature))))

    def log(self, since: int = 0) -> np.ndarray:
        """The writes kept in the ring from write number `since` on (the newest LOG_SIZE at most),
        oldest first: a structured array (t, address, nbytes, b0, b1).
        """
        k = int(self.header['log_next'])
        first = max(since, k - LOG_SIZE)
        idx = np.arange(first, k) % LOG_SIZE
        return self.ring[idx].copy()

    def count(self) -> int:
        return int(self.header['log_next'])
