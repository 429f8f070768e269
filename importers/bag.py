"""Read ``sr_robot_msgs/BiotacAll`` messages from a ROS1 or ROS2 bag (``rosbags``, no ROS install), in chunks.

Per message (one frame of the five Shadow ports, ``tactiles[0..4]`` = ff, mf, rf, lf, th):

- ``header.stamp`` → ``device_time`` (s, the hand's clock);
- ``header.seq`` → ``seq`` (ROS1); ROS2 headers have no ``seq``, so the message index is used
  (noted in ``meta["seq_source"]``);
- the bag's record (receive) time → ``host_time`` (s);
- ``electrodes[N]``, ``pdc``, ``tdc``, ``tac`` per finger: N = 24 for BioTac SPs, 19 for classic
  BioTacs (the count chooses the sensor model unless ``sensor=`` gives it; a port without a
  sensor may send another length, read as zeros);
- PAC: ``pac[]`` when the message has it and it is non-empty (the frame's whole 2.2 kHz
  batch), else ``[pac0, pac1]`` (older messages: the two samples Shadow's driver keeps).

ROS1 bags are read record by record from the start of the file (:func:`.ros1.ros1_messages`), not
through the bag's index: memory stays at one chunk of the bag (the index alone, as
``rosbags`` loads it, grows with the number of messages), messages come in file order (the
order ``rosbag record`` wrote them), and a **truncated** bag — cut inside a chunk or its
index, or never closed (``index_pos = 0``) — still yields every message before the cut. The
reader notes it in ``meta["truncated"]`` (:class:`Ros1Read`); anything malformed before the
end of the file is an :class:`ImportInputError` naming the byte. Message definitions come
from the bag's connection records, deserialised by ``rosbags``.

ROS2 bags (a directory with ``metadata.yaml``; sqlite3 or MCAP) stream through ``rosbags``'
``AnyReader``; definitions come from the bag, or :data:`BIOTAC_MSGS` on a Humble type store.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterator

import numpy as np

from tactile_flow.hardware.biotac import FINGERS

from .recording import CHUNK_FRAMES, ImportInputError, Recording, check_rate, concat
from .ros1 import Ros1Read, ros1_messages

TOPIC = "/rh/tactile"
MSGTYPE = "sr_robot_msgs/msg/BiotacAll"

#: message definitions (newer Shadow form, with ``pac[]``) for bags that do not carry them
BIOTAC_MSGS = {
    "sr_robot_msgs/msg/Biotac": "int16 pac0\nint16 pac1\nint16 pdc\nint16 tac\nint16 tdc\n"
                                "int16[] electrodes\nint16[] pac\n",
    "sr_robot_msgs/msg/BiotacAll": "std_msgs/Header header\nsr_robot_msgs/Biotac[5] tactiles\n",
}


def is_bag(path: Path) -> bool:
    """A ROS1 ``.bag`` file, or a ROS2 bag (a directory with ``metadata.yaml``)."""
    path = Path(path)
    return (path.is_file() and path.suffix == ".bag") or (path.is_dir() and (path / "metadata.yaml").is_file())


def bag_files(path: Path) -> list[Path]:
    """The files that make up the bag (for checksums): the file itself, or every file of a ROS2 bag."""
    path = Path(path)
    return [path] if path.is_file() else sorted(p for p in path.iterdir() if p.is_file())


def biotac_typestore():
    """A ROS2 Humble type store with :data:`BIOTAC_MSGS` registered."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = {}
    for name, text in BIOTAC_MSGS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


# ----------------------------------------------------------------------------- frames
@dataclass
class _Columns:
    """Column lists of the frames of one chunk (see :meth:`BagFile.chunks`)."""

    seq: list = field(default_factory=list)
    stamp: list = field(default_factory=list)
    recv: list = field(default_factory=list)
    el: list = field(default_factory=list)
    pdc: list = field(default_factory=list)
    tdc: list = field(default_factory=list)
    tac: list = field(default_factory=list)
    pac: list = field(default_factory=list)

    def recording(self, meta: dict) -> Recording:
        return Recording(fingers=FINGERS, seq=np.asarray(self.seq, np.int64),
                         device_time=np.asarray(self.stamp, float),
                         host_time=np.asarray(self.recv, np.int64) * 1e-9,
                         electrodes=np.asarray(self.el, np.int64), pdc=np.asarray(self.pdc, np.int64),
                         tdc=np.asarray(self.tdc, np.int64), tac=np.asarray(self.tac, np.int64), pac=self.pac,
                         meta=meta)


class BagFile:
    """A ROS1 or ROS2 bag's ``BiotacAll`` topic read in chunks (the :class:`.recording.Reader`
    protocol), all five fingers (unconnected ones included; see :func:`.recording.decide_fingers`).

    :class:`ImportInputError` (one sentence naming the file) when the bag cannot be read, is
    corrupt, has no such topic (the message lists the topics it has), the topic has another
    type or no messages, or a message does not have five sensors with the same number of
    electrodes (that of ``sensor``, a :class:`tactile.sensor.SensorModel`, when given; else the
    first message's: :attr:`n_taxels` once read).
    """

    finger_names = FINGERS

    def __init__(self, path, topic: str = TOPIC, rate_hz: float | None = None, sensor=None):
        path = Path(path)
        self.sensor = sensor
        self.n_taxels: int | None = sensor.n_taxels if sensor is not None else None
        if path.suffix in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file():
            path = path.parent                   # a ROS2 bag's storage file: read the bag
        self.path, self.topic, self.rate_hz = path, topic, rate_hz
        self.ros2 = path.is_dir()
        self.meta = {"format": "rosbag2" if self.ros2 else "rosbag1", "path": str(path), "topic": topic,
                     "msgtype": MSGTYPE, "messages": None, "seq_source": None, "pac_source": None, "frame_id": None}
        if self.ros2:
            self._open_ros2().close()            # fail now on an unreadable bag or a missing topic

    # -------------------------------------------------------------- sources of raw messages
    def _open_ros2(self):
        from rosbags.highlevel import AnyReader
        try:
            reader = AnyReader([self.path], default_typestore=biotac_typestore())
            reader.open()
        except Exception as exc:                 # noqa: BLE001 - rosbags raises several types
            raise ImportInputError(f"{self.path}: cannot be read as a ROS bag ({type(exc).__name__}: "
                                   f"{_first_line(exc)})") from None
        try:
            conns = [c for c in reader.connections if c.topic == self.topic]
            self._check_topic({(c.topic, c.msgtype) for c in reader.connections})
        except BaseException:
            reader.close()
            raise
        reader.biotac_connections = conns
        return reader

    def _check_topic(self, have: set[tuple[str, str]]) -> None:
        """Refuse a bag without the topic, or with it of another type."""
        types = {t for top, t in have if top == self.topic}
        if not types:
            listing = sorted(f"{top} ({t})" for top, t in have)
            raise ImportInputError(f"{self.path}: no topic {self.topic} in the bag (it has: "
                                   f"{', '.join(listing) or 'no topics'}); give topic=... if the tactile data "
                                   f"are elsewhere")
        if types != {MSGTYPE}:
            raise ImportInputError(f"{self.path}: topic {self.topic} has type {', '.join(sorted(types))}, "
                                   f"expected {MSGTYPE}")

    def _ros2_messages(self) -> Iterator[tuple[int, object]]:
        """``(record time ns, message)`` of the topic, streamed by rosbags."""
        reader = self._open_ros2()
        i = 0
        try:
            it = reader.messages(connections=reader.biotac_connections)
            while True:
                try:
                    conn, t_ns, raw = next(it)
                    msg = reader.deserialize(raw, conn.msgtype)
                except StopIteration:
                    break
                except Exception as exc:         # noqa: BLE001 - sqlite/mcap/serde errors
                    raise ImportInputError(f"{self.path}: corrupt or truncated ROS2 bag: message {i} of "
                                           f"{self.topic} cannot be read ({type(exc).__name__}: "
                                           f"{_first_line(exc)})") from None
                yield t_ns, msg
                i += 1
        finally:
            reader.close()

    def _ros1_messages(self, info: Ros1Read) -> Iterator[tuple[int, object]]:
        """``(record time ns, message)`` of the topic, record by record (:func:`ros1_messages`)."""
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
        store, registered, checked = get_typestore(Stores.EMPTY), set(), set()
        i = 0
        for conn, t_ns, raw in ros1_messages(self.path, info):
            c = info.connections.get(conn)
            if c is None:
                raise ImportInputError(f"{self.path}: corrupt ROS bag: a message on connection {conn} comes "
                                       f"before that connection's record")
            if c[0] != self.topic:
                continue
            if conn not in checked:
                self._check_topic({c[:2]})
                checked.add(conn)
            if c[1] not in registered:
                try:
                    store.register(get_types_from_msg(c[2], c[1]) if c[2].strip()
                                   else _biotac_types())
                except Exception as exc:         # noqa: BLE001 - typesys errors
                    raise ImportInputError(f"{self.path}: the bag's definition of {c[1]} cannot be parsed "
                                           f"({type(exc).__name__}: {_first_line(exc)})") from None
                registered.add(c[1])
            try:
                msg = store.deserialize_ros1(bytes(raw), c[1])
            except Exception as exc:             # noqa: BLE001 - serde errors
                raise ImportInputError(f"{self.path}: corrupt ROS bag: message {i} of {self.topic} cannot be "
                                       f"decoded as {c[1]} ({type(exc).__name__}: {_first_line(exc)})") from None
            yield t_ns, msg
            i += 1
        if not checked and info.cut:
            raise ImportInputError(f"{self.path}: truncated ROS bag: the file ({info.file_bytes} bytes) ends "
                                   f"{info.cut['ends']}, before any complete message on {self.topic}")
        if not checked:
            self._check_topic({c[:2] for c in info.connections.values()})

    # -------------------------------------------------------------- the Reader protocol
    def chunks(self, frames: int = CHUNK_FRAMES) -> Iterator[Recording]:
        """Every message on the topic as :class:`Recording` chunks of at most ``frames`` frames."""
        info = None if self.ros2 else Ros1Read(self.path.stat().st_size)
        messages = self._ros2_messages() if self.ros2 else self._ros1_messages(info)
        cols, n = _Columns(), 0
        has_seq, pac_source, frame_id = True, "pac0, pac1", ""
        for t_ns, msg in messages:
            h = msg.header
            if n == 0:
                has_seq = hasattr(h, "seq")
                frame_id = str(getattr(h, "frame_id", ""))
            if n == 0 and self.n_taxels is None:
                self.n_taxels = _electrode_count(msg, self.path)
            if _add_frame(cols, msg, t_ns, n, has_seq, self.path, self.n_taxels, self.sensor):
                pac_source = "pac[]"
            n += 1
            if len(cols.seq) == frames:
                yield cols.recording(self.meta)
                cols = _Columns()
        if not n:
            raise ImportInputError(f"{self.path}: topic {self.topic} has no messages")
        if cols.seq:
            yield cols.recording(self.meta)
        self.meta.update(messages=n, seq_source="header.seq" if has_seq else "message index (ROS2 headers have no seq)",
                         pac_source=pac_source, frame_id=frame_id, electrodes=self.n_taxels)
        truncated = info.truncation(n) if info else None
        if truncated:
            self.meta["truncated"] = truncated

    def finish(self, rate_hz: float) -> None:
        """Check a given ``rate_hz`` against the rate of the header stamps (Hz, median interval)."""
        check_rate(rate_hz, self.rate_hz, f"{self.path}: header stamps of {self.topic}")


def _electrode_count(msg, path: Path) -> int:
    """Electrodes per sensor of a message: the length of the connected sensors' ``electrodes``."""
    from .recording import UNCONNECTED_PDC
    lengths = {len(b.electrodes) for b in msg.tactiles if b.pdc != UNCONNECTED_PDC} or \
        {len(b.electrodes) for b in msg.tactiles}
    if len(lengths) != 1:
        raise ImportInputError(f"{path}: message 0 has sensors with {sorted(lengths)} electrodes; expected the "
                               f"same number for every sensor")
    return lengths.pop()


def _add_frame(cols: _Columns, msg, t_ns: int, i: int, has_seq: bool, path: Path, n_taxels: int,
               sensor=None) -> bool:
    """Append message ``i`` to ``cols``; True when its PAC came from ``pac[]``."""
    from .recording import UNCONNECTED_PDC
    h = msg.header
    cols.seq.append(int(h.seq) if has_seq else i)
    cols.stamp.append(h.stamp.sec + h.stamp.nanosec * 1e-9)
    cols.recv.append(t_ns)
    tact = list(msg.tactiles)
    if len(tact) != len(FINGERS):
        raise ImportInputError(f"{path}: message {i} has {len(tact)} sensors, expected {len(FINGERS)} "
                               f"({', '.join(FINGERS)})")
    e = [np.asarray(b.electrodes) if len(b.electrodes) == n_taxels or b.pdc != UNCONNECTED_PDC
         else np.zeros(n_taxels, np.int64) for b in tact]            # a port without a sensor: zeros
    if any(len(a) != n_taxels for a in e):
        whose = f"sensor={sensor.name} has" if sensor is not None else "the first message has"
        lengths = sorted({len(b.electrodes) for b in tact if b.pdc != UNCONNECTED_PDC} or {len(a) for a in e})
        raise ImportInputError(f"{path}: message {i} has {lengths} electrodes per sensor; {whose} {n_taxels}")
    cols.el.append(e)
    cols.pdc.append([b.pdc for b in tact])
    cols.tdc.append([b.tdc for b in tact])
    cols.tac.append([b.tac for b in tact])
    batch = [np.asarray(getattr(b, "pac", ()), np.int64) for b in tact]
    if all(len(p) for p in batch) and len({len(p) for p in batch}) == 1:
        cols.pac.append(np.stack(batch))
        return True
    cols.pac.append(np.array([[b.pac0, b.pac1] for b in tact], np.int64))
    return False


def _biotac_types() -> dict:
    from rosbags.typesys import get_types_from_msg
    types = {}
    for name, text in BIOTAC_MSGS.items():
        types.update(get_types_from_msg(text, name))
    return types


def read_bag(path, topic: str = TOPIC, sensor=None) -> Recording:
    """Every ``BiotacAll`` message on ``topic`` of the bag at ``path`` as one :class:`Recording`
    with all five fingers (in memory: for small bags and tests; the import streams the bag with
    :class:`BagFile`). Errors as :class:`BagFile`."""
    reader = BagFile(path, topic, sensor=sensor)
    rec = concat(reader.chunks())
    return replace(rec, meta=dict(reader.meta))


def _first_line(exc: Exception) -> str:
    s = str(exc)
    return s.splitlines()[0] if s else ""
