"""ROS 2 bags of ``sensor_msgs/msg/JointState``: read message by message, written as MCAP.

Read with the pure-Python ``rosbags`` package (no ROS installation): a rosbag2
folder (``metadata.yaml`` with MCAP or sqlite3 storage) or a bare ``.mcap`` /
``.db3`` file. One topic is read: the one given, else the only JointState topic
(an error lists them when there are several, or lists every topic when the one
asked for is missing).

Mapping, per message: ``position``, ``velocity``, ``effort`` -> q, dq, tau,
matched by joint name to the joints asked for (the robot's, in its order; by
default those of the first message). Messages may list the joints in any
order and carry other joints; a message that lacks a joint, or has no
velocities or efforts, is refused with its index. Time is ``header.stamp``
[s], or the log time when the stamp is zero.
"""

from __future__ import annotations

import os
import shutil
import struct
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .layout import Layout

JOINT_STATE = "sensor_msgs/msg/JointState"
DEFAULT_TOPIC = "/joint_states"


def parse_joint_state(raw):
    """A little-endian CDR ``sensor_msgs/msg/JointState`` read without a type system.

    Returns ``(sec, nanosec, names, position, velocity, effort)`` with ``names``
    the raw bytes of the name sequence (a cache key; :func:`decode_names` reads
    them) and the values as float64 views of ``raw``; or None for anything but
    the plain case (big-endian, an empty or short sequence, trailing bytes),
    which the caller hands to ``rosbags``. Layout (alignment counted from the
    end of the 4-byte encapsulation header): int32 sec, uint32 nanosec, string
    frame_id, sequence<string> name, then three sequence<float64>.
    """
    try:
        return _parse_joint_state(memoryview(raw))
    except struct.error:  # a sequence length past the end: rosbags decides (and refuses)
        return None


def _parse_joint_state(buf: memoryview):
    size = len(buf)
    if size < 16 or buf[0] != 0 or buf[1] != 1:
        return None
    unpack = struct.unpack_from
    d = 4
    sec, nsec, n = unpack("<iII", buf, d)
    o = d + 12 + n
    o = d + ((o - d + 3) & ~3)
    (count,) = unpack("<I", buf, o)
    o += 4
    start = o
    for _ in range(count):
        o = d + ((o - d + 3) & ~3)
        (n,) = unpack("<I", buf, o)
        o += 4 + n
        if o > size:
            return None
    names = bytes(buf[start:o])
    values = []
    for _ in range(3):
        o = d + ((o - d + 3) & ~3)
        (m,) = unpack("<I", buf, o)
        o += 4
        if m != count or count == 0:
            return None
        o = d + ((o - d + 7) & ~7)
        if o + 8 * m > size:
            return None
        values.append(np.frombuffer(buf, "<f8", m, o))
        o += 8 * m
    if o != size:
        return None
    return sec, nsec, names, values[0], values[1], values[2]


def decode_names(key: bytes) -> list[str]:
    """The joint names of a name sequence's raw bytes (from :func:`parse_joint_state`)."""
    out, o = [], 0
    while o < len(key):
        o = (o + 3) & ~3
        (n,) = struct.unpack_from("<I", key, o)
        out.append(key[o + 4 : o + 4 + n - 1].decode("utf-8", errors="replace"))
        o += 4 + n
    return out


def is_bag(path: Path) -> bool:
    """Whether ``path`` is a rosbag2 folder or a bare ``.mcap`` / ``.db3`` file."""
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() in (".mcap", ".db3")


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _open_reader(path: Path):
    from rosbags.rosbag2 import Reader

    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # rosbags raises its own ReaderError, FileNotFoundError, ...
        raise DataError(f"cannot read {path} as a ROS 2 bag: {exc}") from exc
    return reader


def _topics_text(reader) -> str:
    items = sorted({(c.topic, c.msgtype) for c in reader.connections})
    return ", ".join(f"{t} ({m})" for t, m in items) or "none"


class BagSource:
    """Rows of one JointState topic of a ROS 2 bag (see the module docstring).

    Attributes: ``path``, ``format`` ("rosbag"), ``topic``, ``layout``,
    ``joint_names``, ``n_rows`` (the topic's message count).
    """

    format = "rosbag"

    def __init__(self, path: Path, topic: str | None = None, joint_names=None):
        self.path = Path(path)
        reader = _open_reader(self.path)
        try:
            conns = [c for c in reader.connections if c.msgtype == JOINT_STATE]
            if topic is not None:
                chosen = [c for c in reader.connections if c.topic == topic]
                if not chosen:
                    raise DataError(
                        f"{self.path} has no topic {topic!r}; its topics: {_topics_text(reader)}"
                    )
                if chosen[0].msgtype != JOINT_STATE:
                    raise DataError(
                        f"topic {topic!r} of {self.path} carries {chosen[0].msgtype}, "
                        f"not {JOINT_STATE}"
                    )
            else:
                topics = sorted({c.topic for c in conns})
                if not topics:
                    raise DataError(
                        f"{self.path} has no {JOINT_STATE} topic; "
                        f"its topics: {_topics_text(reader)}"
                    )
                if len(topics) > 1:
                    raise DataError(
                        f"{self.path} has several {JOINT_STATE} topics: {', '.join(topics)}; "
                        "choose one with --topic (topic=)"
                    )
                topic = topics[0]
                chosen = [c for c in conns if c.topic == topic]
            self.topic = topic
            self._connections = chosen
            self.n_rows = int(sum(c.msgcount for c in chosen))
            first = None
            for conn, _stamp, raw in reader.messages(connections=chosen):
                first = self._decode(raw, conn.msgtype)
                break
        finally:
            reader.close()
        if first is None:
            raise DataError(f"topic {topic!r} of {self.path} holds no message")
        names = [str(n) for n in first.name]
        if joint_names is None:
            joint_names = names
        self.joint_names = tuple(str(j) for j in joint_names)
        missing = [j for j in self.joint_names if j not in names]
        if missing:
            raise DataError(
                f"the JointState messages of {topic!r} in {self.path} lack joint(s) "
                f"{', '.join(missing)} (they carry {', '.join(names)})"
            )
        nv = len(self.joint_names)
        self.layout = Layout(nv, nv, False)

    _store: Any = None

    def _decode(self, raw, msgtype):
        if BagSource._store is None:
            BagSource._store = _typestore()
        try:
            return BagSource._store.deserialize_cdr(raw, msgtype)
        except Exception as exc:  # rosbags' errors, struct.error, UnicodeDecodeError, ...
            raise DataError(
                f"{self.path}: a {msgtype} message of {self.topic!r} is not valid CDR "
                f"({type(exc).__name__}: {exc})"
            ) from exc

    def chunks(self, chunk: int, start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
        """Packed rows of messages ``start:stop``, ``chunk`` messages at a time."""
        lay = self.layout
        nv = lay.nv
        wanted = self.joint_names
        sq, sdq, stau = lay.slices["q"], lay.slices["dq"], lay.slices["tau"]
        order_cache: dict = {}
        order_names: dict = {}
        reader = _open_reader(self.path)
        try:
            buf = np.empty((chunk, lay.width))
            k = 0
            for index, (conn, logtime, raw) in enumerate(
                reader.messages(connections=self._connections)
            ):
                if index < start:
                    continue
                if stop is not None and index >= stop:
                    break
                fast = parse_joint_state(raw)
                if fast is not None:
                    sec, nsec, key, pos, vel, eff = fast
                else:
                    msg = self._decode(raw, conn.msgtype)
                    key = tuple(msg.name)
                    sec, nsec = msg.header.stamp.sec, msg.header.stamp.nanosec
                    pos, vel, eff = msg.position, msg.velocity, msg.effort
                idx = order_cache.get(key)
                if idx is None:
                    names = decode_names(key) if isinstance(key, bytes) else [str(n) for n in key]
                    missing = [j for j in wanted if j not in names]
                    if missing:
                        raise DataError(
                            f"{self.path}: message {index} of {self.topic!r} lists joints "
                            f"{', '.join(names)}, without {', '.join(missing)}: the joint set "
                            "changes within the log"
                        )
                    idx = np.array([names.index(j) for j in wanted], dtype=np.intp)
                    order_cache[key] = idx
                    order_names[key] = names
                n_names = len(order_names[key]) if key in order_names else len(key)
                for field, values in (("position", pos), ("velocity", vel), ("effort", eff)):
                    if fast is not None:
                        break
                    if len(values) != n_names:
                        what = "no" if len(values) == 0 else f"{len(values)} values of"
                        raise DataError(
                            f"{self.path}: message {index} of {self.topic!r} has {what} {field} "
                            f"for its {n_names} joints; q, dq and tau need position, velocity "
                            "and effort"
                        )
                row = buf[k]
                row[0] = sec + 1e-9 * nsec if (sec or nsec) else 1e-9 * logtime
                row[sq] = np.asarray(pos)[idx]
                row[sdq] = np.asarray(vel)[idx]
                row[stau] = np.asarray(eff)[idx]
                k += 1
                if k == chunk:
                    yield buf.copy()
                    k = 0
            if k:
                yield buf[:k].copy()
        finally:
            reader.close()
        del nv


def write_bag(
    path: Path,
    blocks,
    layout: Layout,
    joint_names=None,
    topic: str = DEFAULT_TOPIC,
    bare: bool | None = None,
):
    """Write packed row blocks as JointState messages on ``topic`` with MCAP storage.

    ``bare`` (default: ``path`` ends in ``.mcap``) gives one bare MCAP file, else a
    rosbag2 folder; either is written to a temporary first and renamed into place.
    ``blocks()`` returns an iterator of packed rows (ddq is not written).
    Stamps need ``t >= 0`` [s]: ``header.stamp`` and the log time both carry ``t``.
    """
    path = Path(path)
    names = list(joint_names) if joint_names else [f"j{i}" for i in range(layout.nv)]
    if layout.nq != layout.nv:
        raise DataError(
            f"a JointState bag carries one position per joint, but q has {layout.nq} columns "
            f"for {layout.nv} joints"
        )
    sq, sdq, stau = layout.slices["q"], layout.slices["dq"], layout.slices["tau"]

    def messages(store):
        JointState = store.types[JOINT_STATE]
        Header = store.types["std_msgs/msg/Header"]
        Time = store.types["builtin_interfaces/msg/Time"]
        for block in blocks():
            if block.shape[0] and block[:, 0].min() < 0:
                raise DataError(f"cannot stamp negative times in a ROS bag ({path})")
            for row in block:
                ns = int(round(row[0] * 1e9))
                yield (
                    ns,
                    JointState(
                        header=Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                        name=names,
                        position=np.ascontiguousarray(row[sq]),
                        velocity=np.ascontiguousarray(row[sdq]),
                        effort=np.ascontiguousarray(row[stau]),
                    ),
                )

    return write_messages(path, topic, JOINT_STATE, messages, bare=bare)


def write_messages(path: Path, topic: str, msgtype: str, messages, bare: bool | None = None):
    """Write the messages of one ``topic`` of type ``msgtype`` (e.g.
    ``trajectory_msgs/msg/JointTrajectory``) as a ROS 2 bag with MCAP storage.

    ``messages(store)`` yields ``(log time [ns], message)`` with the messages built from the
    types of ``store`` (rosbags' ROS 2 Humble type store). ``bare`` (default: ``path`` ends
    in ``.mcap``) gives one bare MCAP file, else a rosbag2 folder; either is written to a
    temporary first and renamed into place. Returns ``path``.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer

    path = Path(path)
    if path.exists() and path.is_dir() and not (path / "metadata.yaml").is_file():
        raise DataError(f"{path} is a folder that is not a ROS 2 bag: refusing to replace it")
    store = _typestore()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmpdir = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}."))
    bag = tmpdir / "bag"
    try:
        with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conn = writer.add_connection(topic, msgtype, typestore=store)
            for ns, msg in messages(store):
                writer.write(conn, ns, store.serialize_cdr(msg, msgtype))
        if path.suffix.lower() == ".mcap" if bare is None else bare:
            produced = next(bag.glob("*.mcap"))
            os.chmod(produced, 0o644)
            os.replace(produced, path)
        else:
            old = None
            if path.exists():
                old = tmpdir / "old"
                os.replace(path, old)
            os.replace(bag, path)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    return path
