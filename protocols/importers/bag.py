"""Read ``sr_robot_msgs/BiotacAll`` messages from a ROS1 or ROS2 bag (``rosbags``, no ROS install).

Message definitions come from the bag (ROS1 connection records, ROS2 metadata); a ROS2 bag
without them is read with :data:`BIOTAC_MSGS` registered on a Humble type store.

Per message (one frame of the five Shadow ports, ``tactiles[0..4]`` = ff, mf, rf, lf, th):

- ``header.stamp`` → ``device_time`` (s, the hand's clock);
- ``header.seq`` → ``seq`` (ROS1); ROS2 headers have no ``seq``, so the message index is used
  (noted in ``meta["seq_source"]``);
- the bag's record (receive) time → ``host_time`` (s);
- ``electrodes[24]``, ``pdc``, ``tdc``, ``tac`` per finger;
- PAC: ``pac[]`` when the message has it and it is non-empty (the frame's whole 2.2 kHz
  batch), else ``[pac0, pac1]`` (older messages: the two samples Shadow's driver keeps).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hardware.biotac import FINGERS, N_TAXELS

from .recording import ImportInputError, Recording

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


def read_bag(path, topic: str = TOPIC) -> Recording:
    """Every ``BiotacAll`` message on ``topic`` of the bag at ``path`` as a :class:`Recording`
    with all five fingers (unconnected ones included; see :func:`.recording.select_fingers`).

    Raises :class:`ImportInputError` (one sentence) when the bag cannot be read, has no such
    topic (the message lists the topics it has), the topic has another type or no messages,
    or a message does not have five sensors with 24 electrodes each.
    """
    from rosbags.highlevel import AnyReader
    path = Path(path)
    if path.suffix in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file():
        path = path.parent                       # a ROS2 bag's storage file: read the bag
    try:
        reader = AnyReader([path], default_typestore=biotac_typestore())
        reader.open()
    except Exception as exc:                     # noqa: BLE001 - rosbags raises several types
        raise ImportInputError(f"{path}: cannot be read as a ROS bag ({type(exc).__name__}: "
                               f"{_first_line(exc)})") from None
    try:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            have = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})
            raise ImportInputError(f"{path}: no topic {topic} in the bag (it has: {', '.join(have) or 'no topics'}); "
                                   f"give topic=... if the tactile data are elsewhere")
        types = {c.msgtype for c in conns}
        if types != {MSGTYPE}:
            raise ImportInputError(f"{path}: topic {topic} has type {', '.join(sorted(types))}, expected {MSGTYPE}")
        cols = _columns(reader, conns, path)
        ros2 = bool(reader.is2)
    finally:
        reader.close()
    seq_source = "header.seq" if cols["has_seq"] else "message index (ROS2 headers have no seq)"
    meta = {"format": "rosbag2" if ros2 else "rosbag1", "path": str(path), "topic": topic, "msgtype": MSGTYPE,
            "messages": len(cols["seq"]), "seq_source": seq_source,
            "pac_source": cols["pac_source"], "frame_id": cols["frame_id"]}
    return Recording(fingers=FINGERS, seq=cols["seq"], device_time=cols["device_time"],
                     host_time=cols["host_time"], electrodes=cols["electrodes"], pdc=cols["pdc"],
                     tdc=cols["tdc"], tac=cols["tac"], pac=cols["pac"], meta=meta)


def _columns(reader, conns, path: Path) -> dict:
    """Deserialise every message into column arrays (see :func:`read_bag`)."""
    seq, stamp, recv, el, pdc, tdc, tac, pac = [], [], [], [], [], [], [], []
    has_seq, pac_source, frame_id = True, "pac0, pac1", ""
    for i, (conn, t_ns, raw) in enumerate(reader.messages(connections=conns)):
        msg = reader.deserialize(raw, conn.msgtype)
        h = msg.header
        if i == 0:
            has_seq = hasattr(h, "seq")
            frame_id = str(getattr(h, "frame_id", ""))
        seq.append(int(h.seq) if has_seq else i)
        stamp.append(h.stamp.sec + h.stamp.nanosec * 1e-9)
        recv.append(t_ns)
        tact = list(msg.tactiles)
        if len(tact) != len(FINGERS):
            raise ImportInputError(f"{path}: message {i} has {len(tact)} sensors, expected {len(FINGERS)} "
                                   f"({', '.join(FINGERS)})")
        e = [np.asarray(b.electrodes) for b in tact]
        if any(len(a) != N_TAXELS for a in e):
            raise ImportInputError(f"{path}: message {i} has {sorted({len(a) for a in e})} electrodes per sensor, "
                                   f"expected {N_TAXELS} (BioTac SP)")
        el.append(e)
        pdc.append([b.pdc for b in tact])
        tdc.append([b.tdc for b in tact])
        tac.append([b.tac for b in tact])
        batch = [np.asarray(getattr(b, "pac", ()), np.int64) for b in tact]
        if all(len(p) for p in batch) and len({len(p) for p in batch}) == 1:
            pac_source = "pac[]"
            pac.append(np.stack(batch))
        else:
            pac.append(np.array([[b.pac0, b.pac1] for b in tact], np.int64))
    if not seq:
        raise ImportInputError(f"{path}: topic {conns[0].topic} has no messages")
    return {"seq": np.asarray(seq, np.int64), "device_time": np.asarray(stamp, float),
            "host_time": np.asarray(recv, np.int64) * 1e-9,
            "electrodes": np.asarray(el, np.int64), "pdc": np.asarray(pdc, np.int64),
            "tdc": np.asarray(tdc, np.int64), "tac": np.asarray(tac, np.int64), "pac": pac,
            "has_seq": has_seq, "pac_source": pac_source, "frame_id": frame_id}


def _first_line(exc: Exception) -> str:
    s = str(exc)
    return s.splitlines()[0] if s else ""
