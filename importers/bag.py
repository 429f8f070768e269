"""Read ``sr_robot_msgs/BiotacAll`` messages from a ROS1 or ROS2 bag (``rosbags``, no ROS install), in chunks.

Per message (one frame of the five Shadow ports, ``tactiles[0..4]`` = ff, mf, rf, lf, th):

- ``header.stamp`` → ``device_time`` (s, the hand's clock);
- ``header.seq`` → ``seq`` (ROS1); ROS2 headers have no ``seq``, so the message index is used
  (noted in ``meta["seq_source"]``);
- the bag's record (receive) time → ``host_time`` (s);
- ``electrodes[24]``, ``pdc``, ``tdc``, ``tac`` per finger;
- PAC: ``pac[]`` when the message has it and it is non-empty (the frame's whole 2.2 kHz
  batch), else ``[pac0, pac1]`` (older messages: the two samples Shadow's driver keeps).

ROS1 bags are read record by record from the start of the file (:func:`ros1_messages`), not
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

import bz2
import struct
from dataclasses import dataclass, field, replace
from pathlib import Path, PurePosixPath
from typing import Iterator

import numpy as np

from hardware.biotac import FINGERS, N_TAXELS

from .recording import CHUNK_FRAMES, ImportInputError, Recording, check_rate, concat

TOPIC = "/rh/tactile"
MSGTYPE = "sr_robot_msgs/msg/BiotacAll"

#: message definitions (newer Shadow form, with ``pac[]``) for bags that do not carry them
BIOTAC_MSGS = {
    "sr_robot_msgs/msg/Biotac": "int16 pac0\nint16 pac1\nint16 pdc\nint16 tac\nint16 tdc\n"
                                "int16[] electrodes\nint16[] pac\n",
    "sr_robot_msgs/msg/BiotacAll": "std_msgs/Header header\nsr_robot_msgs/Biotac[5] tactiles\n",
}

#: largest ROS1 record (a chunk, decompressed) read into memory, bytes; rosbag writes ~1 MB
MAX_RECORD_BYTES = 256 << 20
_MAGIC = b"#ROSBAG V2.0\n"
_OP_MSG, _OP_BAG_HEADER, _OP_INDEX, _OP_CHUNK, _OP_CHUNK_INFO, _OP_CONNECTION = 2, 3, 4, 5, 6, 7


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


# ----------------------------------------------------------------------------- ROS1, record by record
class _Corrupt(Exception):
    """A malformed record (internal; becomes an ImportInputError naming the byte)."""


class _Cut(Exception):
    """The file (or a truncated chunk's data) ends inside a record (internal)."""


@dataclass
class Ros1Read:
    """What :func:`ros1_messages` found besides the messages (filled while it runs).

    Attributes:
        file_bytes: size of the file.
        index_pos: where the bag header says the index starts (0: the bag was never closed).
        chunks_expected: chunks the bag header announces (0 when never closed).
        chunks_read: chunks read completely.
        connections: ``{conn id: (topic, msgtype, message definition)}``.
        cut: ``None`` for a complete bag, else where it ends: ``{"at_byte", "ends"}``, ``at_byte``
            the start of the incomplete record (the file's size when it ends between records),
            ``ends`` e.g. ``inside chunk 3``, ``inside the index data of chunk 2``, ``inside the
            bag index``, ``after chunk 4 without an index (the bag was never closed)``.
    """

    file_bytes: int
    index_pos: int = 0
    chunks_expected: int = 0
    chunks_read: int = 0
    connections: dict = field(default_factory=dict)
    cut: dict | None = None

    def truncation(self, messages: int) -> dict | None:
        """``meta["truncated"]``: where the file ends, what was read, what is lost (JSON-ready);
        ``None`` for a complete bag."""
        if self.cut is None:
            return None
        complete = self.index_pos > 0 and self.chunks_read >= self.chunks_expected > 0
        lost = ("none: every chunk the bag header announces was read" if complete else
                "whatever was recorded after the cut (unknown)")
        return {"file_bytes": self.file_bytes, "cut_record_at_byte": self.cut["at_byte"], "ends": self.cut["ends"],
                "index_pos": self.index_pos or None, "chunks_read": self.chunks_read,
                "chunks_in_header": self.chunks_expected or None, "messages_read": messages,
                "messages_lost": lost,
                "note": "truncated bag: every complete message before the end of the file was imported"}


def _fields(buf) -> dict[str, bytes]:
    """A ROS1 record header: repeated ``<uint32 length><name>=<value>``."""
    out, i, n = {}, 0, len(buf)
    while i < n:
        if i + 4 > n:
            raise _Corrupt("a header field length is cut")
        (k,) = struct.unpack_from("<I", buf, i)
        if i + 4 + k > n:
            raise _Corrupt("a header field runs past its header")
        name, sep, value = bytes(buf[i + 4:i + 4 + k]).partition(b"=")
        if not sep:
            raise _Corrupt("a header field without '='")
        out[name.decode("latin-1")] = value
        i += 4 + k
    return out


def _uint(fields: dict, name: str, size: int = 4) -> int:
    """An unsigned little-endian integer field of ``size`` bytes."""
    v = fields.get(name)
    if v is None or len(v) != size:
        raise _Corrupt(f"field {name!r} missing or not {size} bytes")
    return int.from_bytes(v, "little")


def _op(fields: dict) -> int:
    op = fields.get("op")
    if op is None or len(op) != 1:
        raise _Corrupt("record without an op code")
    return op[0]


def _records(buf, partial: bool) -> Iterator[tuple[dict, memoryview]]:
    """The records of a chunk's (decompressed) data: ``(header fields, data)``. An incomplete
    last record is the end of a truncated chunk (``partial``), else corruption."""
    view, i, n = memoryview(buf), 0, len(buf)
    while i < n:
        try:
            if i + 4 > n:
                raise _Cut
            (hl,) = struct.unpack_from("<I", view, i)
            if i + 8 + hl > n:
                raise _Cut
            hdr = _fields(view[i + 4:i + 4 + hl])
            (dl,) = struct.unpack_from("<I", view, i + 4 + hl)
            if i + 8 + hl + dl > n:
                raise _Cut
        except _Cut:
            if partial:
                return
            raise _Corrupt("a record inside a chunk runs past the chunk") from None
        yield hdr, view[i + 8 + hl:i + 8 + hl + dl]
        i += 8 + hl + dl


def _decompress(compression: bytes, data: bytes, size: int, partial: bool) -> bytes:
    """A chunk's data, decompressed (at most ``size`` bytes); of a cut chunk, what its
    available bytes hold."""
    if compression == b"none":
        out = data
    elif compression == b"bz2":
        try:
            out = bz2.BZ2Decompressor().decompress(data, max_length=size + 1)
        except (OSError, EOFError, ValueError) as exc:
            raise _Corrupt(f"bz2 chunk does not decompress ({exc})") from None
    elif compression == b"lz4":
        import lz4.frame                         # a dependency of rosbags
        try:
            out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1)
        except RuntimeError as exc:
            raise _Corrupt(f"lz4 chunk does not decompress ({exc})") from None
    else:
        raise _Corrupt(f"unknown chunk compression {compression.decode('latin-1')!r}")
    if len(out) > size or (not partial and len(out) != size):
        raise _Corrupt(f"chunk decompresses to {len(out)} bytes, its header says {size}")
    return out


def _topic(name: str) -> str:
    """A topic as ``rosbags`` names it (one leading slash kept, empty parts dropped)."""
    return f'{"/" * name.startswith("/")}{"/".join(x for x in name.split("/") if x)}'


def _msgtype(name: str) -> str:
    """ROS1 ``pkg/Type`` as ``pkg/msg/Type``."""
    p = PurePosixPath(name)
    return str(p if p.parent.name in ("msg", "action") else p.parent / "msg" / p.name)


def _connection(hdr: dict, data) -> tuple[int, tuple[str, str, str]]:
    conn = _uint(hdr, "conn")
    info = _fields(data)
    text = {k: v.decode("utf-8", "replace") for k, v in info.items()}
    topic = _topic(hdr.get("topic", b"").decode("utf-8", "replace") or text.get("topic", ""))
    return conn, (topic, _msgtype(text.get("type", "")), text.get("message_definition", ""))


def ros1_messages(path: Path, info: Ros1Read) -> Iterator[tuple[int, int, memoryview]]:
    """``(conn id, record time ns, serialized message)`` of every message of a ROS1 bag (format
    2.0), in file order, reading one record (at most one chunk) at a time.

    Connections go to ``info.connections`` as they appear (a chunk holds a connection's
    record before its first message). At the end of the file inside a record, the
    messages before the cut are yielded and ``info.cut`` says where; a malformed record is
    :class:`ImportInputError` naming the byte.
    """
    size = info.file_bytes
    with open(path, "rb") as f:
        _check_magic(f.read(len(_MAGIC)), path, size)
        pos = len(_MAGIC)
        while pos < size:
            try:
                hdr, data_pos, dl = _read_header(f, pos)
                op = _op(hdr)
                if pos == len(_MAGIC) and op != _OP_BAG_HEADER:
                    raise _Corrupt("the first record is not the bag header")
                if op == _OP_CHUNK:
                    yield from _chunk(f, hdr, data_pos, dl, size, info)
                    if data_pos + dl > size:
                        info.cut = {"at_byte": pos, "ends": f"inside chunk {info.chunks_read + 1}"}
                        return
                    info.chunks_read += 1
                elif data_pos + dl > size:
                    raise _Cut
                elif op == _OP_BAG_HEADER:
                    info.index_pos = _uint(hdr, "index_pos", 8)
                    info.chunks_expected = _uint(hdr, "chunk_count")
                    _index_connections(f, info, _uint(hdr, "conn_count"))
                elif op in (_OP_CONNECTION, _OP_MSG):
                    if dl > MAX_RECORD_BYTES:
                        raise _Corrupt(f"a record of {dl} bytes")
                    f.seek(data_pos)
                    data = f.read(dl)
                    if op == _OP_CONNECTION:
                        conn, c = _connection(hdr, data)
                        info.connections.setdefault(conn, c)
                    else:
                        yield _uint(hdr, "conn"), _time_ns(hdr), memoryview(data)
                elif op not in (_OP_INDEX, _OP_CHUNK_INFO):
                    raise _Corrupt(f"unknown record op code {op}")
                pos = data_pos + dl
            except _Cut:
                if pos == len(_MAGIC):
                    raise ImportInputError(f"{path}: cannot be read as a ROS bag (truncated: the file ends inside "
                                           f"its bag header, {size} bytes)") from None
                info.cut = {"at_byte": pos, "ends": _section(f, pos, info)}
                return
            except _Corrupt as exc:
                raise ImportInputError(f"{path}: corrupt ROS bag at byte {pos} ({exc}); it cannot be read past "
                                       f"this point") from None
    if not info.index_pos:
        info.cut = {"at_byte": size, "ends": f"after chunk {info.chunks_read} without an index (the bag was "
                                             f"never closed)"}
    elif info.index_pos > size:
        info.cut = {"at_byte": size, "ends": f"after chunk {info.chunks_read}, before its index"}


def _check_magic(magic: bytes, path: Path, size: int) -> None:
    """Refuse a file that does not start as a ROS1 bag of format 2.0."""
    if magic == _MAGIC:
        return
    if not magic:
        what = "empty file"
    elif _MAGIC.startswith(magic):
        what = f"truncated: the file ends inside its first line, {size} bytes"
    elif magic.startswith(b"#ROSBAG V"):
        what = f"version {magic[9:12].decode('latin-1')} is not supported, only 2.0"
    else:
        what = "not a ROS1 bag: it does not start with '#ROSBAG V2.0'"
    raise ImportInputError(f"{path}: cannot be read as a ROS bag ({what})")


def _index_connections(f, info: Ros1Read, count: int) -> None:
    """Connections from the bag's index (a closed bag), so a message whose chunk lacks its
    connection record can still be read; nothing if the index is missing or damaged."""
    pos = info.index_pos
    if not 0 < pos < info.file_bytes:
        return
    try:
        for _ in range(count):
            hdr, data_pos, dl = _read_header(f, pos)
            if _op(hdr) != _OP_CONNECTION or data_pos + dl > info.file_bytes or dl > MAX_RECORD_BYTES:
                return
            f.seek(data_pos)
            conn, c = _connection(hdr, f.read(dl))
            info.connections.setdefault(conn, c)
            pos = data_pos + dl
    except (_Cut, _Corrupt, struct.error):
        return


def _section(f, pos: int, info: Ros1Read) -> str:
    """Which part of the bag a record cut at ``pos`` belongs to."""
    if info.index_pos and pos >= info.index_pos:
        return "inside the bag index"
    try:                                         # the op of the cut record, if its header is there
        hdr, _, _ = _read_header(f, pos)
        return {_OP_CHUNK: f"inside chunk {info.chunks_read + 1}",
                _OP_INDEX: f"inside the index data of chunk {info.chunks_read}"}.get(_op(hdr), "between chunks")
    except (_Cut, _Corrupt, struct.error):
        return f"inside a record header, after {info.chunks_read} complete chunk(s)"


def _read_header(f, pos: int) -> tuple[dict, int, int]:
    """Header fields of the record at ``pos``, where its data start, their length."""
    f.seek(pos)
    raw = f.read(4)
    if len(raw) < 4:
        raise _Cut
    (hl,) = struct.unpack("<I", raw)
    if hl > MAX_RECORD_BYTES:
        raise _Corrupt(f"a record header of {hl} bytes")
    head = f.read(hl + 4)
    if len(head) < hl + 4:
        raise _Cut
    hdr = _fields(head[:hl])
    (dl,) = struct.unpack("<I", head[hl:])
    return hdr, pos + 8 + hl, dl


def _time_ns(hdr: dict) -> int:
    t = hdr.get("time")
    if t is None or len(t) != 8:
        raise _Corrupt("a message record without an 8-byte time")
    sec, nsec = struct.unpack("<II", t)
    return sec * 10**9 + nsec


def _chunk(f, hdr: dict, data_pos: int, dl: int, size: int, info: Ros1Read):
    """The messages (and connections) of the chunk record whose data start at ``data_pos``."""
    uncompressed = _uint(hdr, "size")
    if uncompressed > MAX_RECORD_BYTES or dl > MAX_RECORD_BYTES:
        raise _Corrupt(f"a chunk of {max(uncompressed, dl)} bytes, more than this reader's limit of "
                       f"{MAX_RECORD_BYTES >> 20} MiB")
    partial = data_pos + dl > size
    f.seek(data_pos)
    data = f.read(min(dl, size - data_pos))
    body = _decompress(hdr.get("compression", b"none"), data, uncompressed, partial)
    for rh, rdata in _records(body, partial):
        op = _op(rh)
        if op == _OP_CONNECTION:
            conn, c = _connection(rh, rdata)
            info.connections.setdefault(conn, c)
        elif op == _OP_MSG:
            yield _uint(rh, "conn"), _time_ns(rh), rdata
        else:
            raise _Corrupt(f"record op code {op} inside a chunk")


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
    type or no messages, or a message does not have five sensors with 24 electrodes each.
    """

    finger_names = FINGERS

    def __init__(self, path, topic: str = TOPIC, rate_hz: float | None = None):
        path = Path(path)
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
            if _add_frame(cols, msg, t_ns, n, has_seq, self.path):
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
                         pac_source=pac_source, frame_id=frame_id)
        truncated = info.truncation(n) if info else None
        if truncated:
            self.meta["truncated"] = truncated

    def finish(self, rate_hz: float) -> None:
        """Check a given ``rate_hz`` against the rate of the header stamps (Hz, median interval)."""
        check_rate(rate_hz, self.rate_hz, f"{self.path}: header stamps of {self.topic}")


def _add_frame(cols: _Columns, msg, t_ns: int, i: int, has_seq: bool, path: Path) -> bool:
    """Append message ``i`` to ``cols``; True when its PAC came from ``pac[]``."""
    h = msg.header
    cols.seq.append(int(h.seq) if has_seq else i)
    cols.stamp.append(h.stamp.sec + h.stamp.nanosec * 1e-9)
    cols.recv.append(t_ns)
    tact = list(msg.tactiles)
    if len(tact) != len(FINGERS):
        raise ImportInputError(f"{path}: message {i} has {len(tact)} sensors, expected {len(FINGERS)} "
                               f"({', '.join(FINGERS)})")
    e = [np.asarray(b.electrodes) for b in tact]
    if any(len(a) != N_TAXELS for a in e):
        raise ImportInputError(f"{path}: message {i} has {sorted({len(a) for a in e})} electrodes per sensor, "
                               f"expected {N_TAXELS} (BioTac SP)")
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


def read_bag(path, topic: str = TOPIC) -> Recording:
    """Every ``BiotacAll`` message on ``topic`` of the bag at ``path`` as one :class:`Recording`
    with all five fingers (in memory: for small bags and tests; the import streams the bag with
    :class:`BagFile`). Errors as :class:`BagFile`."""
    reader = BagFile(path, topic)
    rec = concat(reader.chunks())
    return replace(rec, meta=dict(reader.meta))


def _first_line(exc: Exception) -> str:
    s = str(exc)
    return s.splitlines()[0] if s else ""
