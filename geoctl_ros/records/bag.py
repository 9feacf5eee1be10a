"""Flight records as rosbag2 bags, through rosbags (no rclpy): what ``record`` writes, as
``ros2 bag record -s mcap`` (or ``-s sqlite3``) would (a folder with ``metadata.yaml`` and the
storage file), and what ``report`` reads, from any rosbag2 bag of these topics.

Messages go in as the bytes rclpy serialises (CDR) and come out as rosbags' message objects, whose
fields have the ROS names (``msg.pose.orientation.x``).
"""
import os
from pathlib import Path
import queue
import tempfile
import threading
import time
from typing import NamedTuple

from rosbags.highlevel import AnyReader
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
import yaml

from geoctl_ros.params.topics import CONTROLLER_PARAMETERS, RECORDED_NAMES

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
STORAGES = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
CHECKPOINT_S = 1.0           # what is written is on disk (a chunk closed, a commit) this often


def _qos(topic):
    """The offered QoS of metadata.yaml (deadline, lifespan and lease at their defaults)."""
    zero = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, topic.depth,
               QosReliability.RELIABLE if topic.reliable else QosReliability.BEST_EFFORT,
               QosDurability.TRANSIENT_LOCAL if topic.transient_local else QosDurability.VOLATILE,
               zero, zero, QosLiveliness.AUTOMATIC, zero, False)


class BagWriter:
    """A bag being written on a thread of its own: put() never waits for the disk.

    Every CHECKPOINT_S what was written is made durable (the MCAP chunk closed and flushed, the
    sqlite3 transaction committed), so a recorder killed mid-flight loses at most that much.
    """

    def __init__(self, path, topics, storage='mcap'):
        """Create the bag at path (which must not exist) with these topics (by the names they
        are written under), CONTROLLER_PARAMETERS and RECORDED_NAMES; raises ValueError when it
        cannot.
        """
        if storage not in STORAGES:
            raise ValueError('storage must be one of %s, not %r' % (sorted(STORAGES), storage))
        self.path = path
        topics = list(topics) + [CONTROLLER_PARAMETERS, RECORDED_NAMES]
        self.counts = {t.name: 0 for t in topics}
        self.dropped = 0
        self.error = None              # what stopped the writer thread, if anything did
        self._queue = queue.Queue(maxsize=100_000)
        opened = queue.Queue()
        # (sqlite3 objects belong to the thread that made them: the thread opens the bag too)
        self._thread = threading.Thread(target=self._run, name='bag writer', daemon=True,
                                        args=(topics, STORAGES[storage], opened))
        self._thread.start()
        problem = opened.get()
        if problem is not None:
            self._thread.join()
            raise ValueError('%s: cannot write a bag there: %s' % (path, problem))

    def put(self, topic, stamp_ns, data):
        """Queue one serialised message received at stamp_ns (ns since the epoch); counted as
        dropped when the queue is full or the writer has stopped (a full disk).
        """
        if self.error is not None:
            self.dropped += 1
            return
        try:
            self._queue.put_nowait((topic, stamp_ns, bytes(data)))
        except queue.Full:
            self.dropped += 1

    def _run(self, topics, plugin, opened):
        try:
            writer = Writer(self.path, version=8, storage_plugin=plugin)
            writer.open()
            connections = {t.name: writer.add_connection(
                t.name, t.type, typestore=TYPESTORE, offered_qos_profiles=[_qos(t)])
                for t in topics}
        except Exception as e:
            opened.put(e)
            return
        opened.put(None)
        next_checkpoint = time.monotonic() + CHECKPOINT_S
        try:
            while True:
                try:
                    item = self._queue.get(timeout=0.1)
                except queue.Empty:
                    item = ()
                if item is None:
                    break
                if item:
                    topic, stamp, data = item
                    writer.write(connections[topic], stamp, data)
                    self.counts[topic] += 1
                if time.monotonic() >= next_checkpoint:
                    _checkpoint(writer)
                    next_checkpoint = time.monotonic() + CHECKPOINT_S
        except Exception as e:       # a full disk: stop writing, keep what is on disk
            self.error = e
        finally:
            try:
                writer.close()
            except Exception as e:
                self.error = self.error or e

    def close(self):
        """Write what is queued and close the bag (metadata.yaml with the counts). It never
        waits on a writer that has stopped (a full disk): what was on disk stays readable.
        """
        while self._thread.is_alive():
            try:
                self._queue.put(None, timeout=0.1)
                break
            except queue.Full:
                continue
        self._thread.join()




def _checkpoint(writer):
    """Make what was written durable: rosbags keeps a chunk (MCAP) or a transaction (sqlite3)
    open until it is large or the bag is closed; both are reached through its storage object
    (rosbags 0.11, pinned).
    """
    storage = writer.storage
    if hasattr(storage, 'close_chunk'):
        if storage.chunk.bio.tell():
            storage.close_chunk()
        storage.bio.flush()
        os.fsync(storage.bio.fileno())      # on the disk, not in the page cache
    elif hasattr(storage, 'conn'):
        storage.conn.commit()


class Message(NamedTuple):
    """One recorded message: receipt time (s since the epoch) and the message object."""

    t: float
    msg: object


def read_bag(path, topics=None):
    """{topic: [Message, ...]} of the bag at path (MCAP or sqlite3), in receipt order; only the
    named topics when given. A bag whose writer was killed (no metadata.yaml; an MCAP file cut
    mid-chunk) is read up to its last complete chunk or commit. Raises ValueError for what is not
    a bag.
    """
    with tempfile.TemporaryDirectory() as tmp:
        try:
            return _read(_readable(path, tmp), topics)
        except Exception as e:        # rosbags' reader errors name what is wrong with the file
            if not os.path.isfile(os.path.join(path, 'metadata.yaml')):
                raise ValueError('%s: cannot be read as a rosbag2 bag: %s' % (path, e)) from None
            first = e
        try:         # metadata.yaml, and a storage file cut after it was written: mend that
            return _read(_readable(path, tmp, metadata=False), topics)
        except Exception as e:
            raise ValueError('%s: cannot be read as a rosbag2 bag: %s (and without its '
                             'metadata.yaml: %s)' % (path, first, e)) from None


def by_package_names(topics):
    """read_bag's {topic: [Message, ...]} with each topic the recorder heard under another name
    (a remapped pose or imu: its real name) under its package name again, as the bag's
    RECORDED_NAMES says (a bag without it, from ``ros2 bag record``, as it is).
    """
    stored = topics.get(RECORDED_NAMES.name)
    if not stored:
        return topics
    try:
        names = yaml.safe_load(stored[-1].msg.data) or {}
    except yaml.YAMLError:
        return topics
    out = dict(topics)
    if isinstance(names, dict):
        for package, real in names.items():
            if isinstance(real, str) and real in out and package not in out:
                out[package] = out.pop(real)
    return out


def _read(source, topics):
    with AnyReader([source], default_typestore=TYPESTORE) as reader:
        wanted = [c for c in reader.connections if topics is None or c.topic in topics]
        out = {c.topic: [] for c in wanted}
        for conn, stamp, raw in reader.messages(connections=wanted):
            msg = reader.deserialize(raw, conn.msgtype)
            out[conn.topic].append(Message(stamp * 1e-9, msg))
    return out


def _readable(path, tmp, metadata=True):
    """What rosbags can open for the bag at path: the folder when it has metadata.yaml (and
    metadata is True), else its storage file (an MCAP file cut short is mended into tmp first).
    """
    if not os.path.isdir(path):
        raise ValueError('%s is not a rosbag2 bag (not a folder)' % path)
    if metadata and os.path.isfile(os.path.join(path, 'metadata.yaml')):
        return Path(path)
    files = sorted(f for f in os.listdir(path) if f.endswith(('.mcap', '.db3')))
    if not files:
        raise ValueError('%s is not a rosbag2 bag (no metadata.yaml, no .mcap or .db3 file)'
                         % path)
    name = os.path.join(path, files[0])
    if name.endswith('.db3'):
        return Path(name)
    mended = os.path.join(tmp, files[0])
    _mend_mcap(name, mended)
    return Path(mended)


_MCAP_MAGIC = b'\x89MCAP0\r\n'


def _mend_mcap(src, dst):
    """Copy the MCAP file src up to its last complete record and close it as a writer would
    (a data-end record and a footer without a summary), so that a reader scans it.
    """
    with open(src, 'rb') as f:
        data = f.read()
    if not data.startswith(_MCAP_MAGIC):
        raise ValueError('%s is not an MCAP file' % src)
    end = pos = len(_MCAP_MAGIC)
    while pos + 9 <= len(data):
        size = int.from_bytes(data[pos + 1:pos + 9], 'little')
        if pos + 9 + size > len(data) or data[pos] in (0x0F, 0x02):   # cut, or already closed
            break
        pos += 9 + size
        end = pos
    with open(dst, 'wb') as f:
        f.write(data[:end])
        f.write(bytes([0x0F]) + (4).to_bytes(8, 'little') + bytes(4))           # data end
        f.write(bytes([0x02]) + (20).to_bytes(8, 'little') + bytes(20))         # footer
        f.write(_MCAP_MAGIC)
