"""A ROS1 bag (format 2.0) read record by record from the start of the file, without ``rosbags``'
index: memory stays at one chunk, messages come in file order, and a truncated bag (cut inside
a chunk or its index, or never closed) still yields every message before the cut
(:class:`Ros1Read` says where it ends). Anything malformed before the end of the file is an
:class:`~importers.recording.ImportInputError` naming the byte. What the messages mean is
:mod:`importers.bag`'s business.
"""

from __future__ import annotations

import bz2
import struct
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Iterator

from .recording import ImportInputError

#: largest ROS1 record (a chunk, decompressed) read into memory, bytes; rosbag writes ~1 MB
MAX_RECORD_BYTES = 256 << 20
_MAGIC = b"#ROSBAG V2.0\n"
_OP_MSG, _OP_BAG_HEADER, _OP_INDEX, _OP_CHUNK, _OP_CHUNK_INFO, _OP_CONNECTION = 2, 3, 4, 5, 6, 7


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
