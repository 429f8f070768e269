"""A roslibpy connection to a rosbridge server, with a bounded connect and link-loss detection.

roslibpy retries an unreachable server forever and reports a lost link only through an
event; :class:`RosbridgeConnection` turns both into typed errors:

- :meth:`~RosbridgeConnection.open` probes the TCP port first (a refused or unroutable
  address fails at once with its reason), then waits at most ``connect_timeout_s`` for the
  websocket handshake, and raises :class:`RosbridgeUnreachableError` ("unreachable
  rosbridge at ws://host:port: <reason>; hint: ...") after stopping roslibpy's retries;
- a websocket close that we did not ask for sets :attr:`~RosbridgeConnection.lost`, which
  the devices turn into :class:`~hardware.errors.DeviceDisconnectedError`.

    conn = RosbridgeConnection(RosbridgeConfig("ws://10.0.0.2:9090"), who="hand").open()
    topic = conn.subscribe("/joint_states", "sensor_msgs/JointState", callback)
    conn.close()
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from dataclasses import dataclass, field
from urllib.parse import urlparse

from .errors import ConfigError, DeviceTimeoutError, require_positive

log = logging.getLogger(__name__)

HINT = ("is the hand's ROS stack running with rosbridge_server "
        "(roslaunch rosbridge_server rosbridge_websocket.launch), and is the address in "
        "hardware.rosbridge.url right? For a rehearsal start tactile-emulate")


class RosbridgeUnreachableError(DeviceTimeoutError):
    """No rosbridge server answered at the configured URL within the connect timeout."""


@dataclass
class RosbridgeConfig:
    """Where rosbridge listens and how long to wait for it.

    Attributes:
        url: ``ws://host:port`` of ``rosbridge_websocket`` (default port 9090).
        connect_timeout_s: the longest ``open()`` waits for the websocket handshake (s).
        stale_timeout_s: a subscribed stream silent this long (s) after its first message is
            a :class:`~hardware.errors.DeviceTimeoutError` (the server hung).
        transport: roslibpy transport, ``twisted`` (its default) or ``asyncio``.
    """

    url: str = "ws://127.0.0.1:9090"
    connect_timeout_s: float = 5.0
    stale_timeout_s: float = 0.5
    transport: str = "twisted"
    key: str = field(default="hardware.rosbridge", repr=False)

    def __post_init__(self):
        parts = urlparse(str(self.url))
        if parts.scheme not in ("ws", "wss") or not parts.hostname:
            raise ConfigError(f"{self.key}.url", f"expected ws://host:port, got {self.url!r}")
        try:
            parts.port
        except ValueError:
            raise ConfigError(f"{self.key}.url", f"bad port in {self.url!r}") from None
        require_positive(self, ("connect_timeout_s", "stale_timeout_s"), self.key)
        if self.transport not in ("twisted", "asyncio"):
            raise ConfigError(f"{self.key}.transport", f"expected twisted or asyncio, got {self.transport!r}")

    @property
    def host(self) -> str:
        return urlparse(self.url).hostname

    @property
    def port(self) -> int:
        return urlparse(self.url).port or (443 if self.url.startswith("wss") else 9090)


class RosbridgeConnection:
    """One websocket to rosbridge; ``lost`` says why the link went away (None while it is up)."""

    def __init__(self, cfg: RosbridgeConfig, who: str):
        self.cfg, self.who = cfg, who
        self.ros = None
        self.lost: str | None = None
        self._closing = False
        self._topics = []

    @property
    def is_open(self) -> bool:
        return self.ros is not None and self.lost is None

    def open(self) -> "RosbridgeConnection":
        """Connect within ``connect_timeout_s`` or raise :class:`RosbridgeUnreachableError`."""
        import roslibpy

        if self.ros is not None:
            return self
        t0 = time.monotonic()
        self._probe()
        self._closing, self.lost = False, None
        ros = roslibpy.Ros(self.cfg.host, self.cfg.port, is_secure=self.cfg.url.startswith("wss"),
                           transport=self.cfg.transport)
        ready = threading.Event()
        ros.factory.on_ready(lambda proto: ready.set())
        ros.factory.manager.run()
        if not ready.wait(max(0.1, self.cfg.connect_timeout_s - (time.monotonic() - t0))):
            _stop_retrying(ros)
            raise RosbridgeUnreachableError(
                f"{self.who}: unreachable rosbridge at {self.cfg.url}: no websocket handshake within "
                f"{self.cfg.key}.connect_timeout_s={self.cfg.connect_timeout_s} s (a TCP port answers, "
                f"but is it rosbridge?); hint: {HINT}")
        ros.on("close", self._on_close)
        self.ros = ros
        return self

    def subscribe(self, topic: str, msg_type: str, callback, queue_length: int = 0):
        """Subscribe ``callback(message_dict)`` to ``topic``; returns the roslibpy Topic."""
        import roslibpy

        t = roslibpy.Topic(self.ros, topic, msg_type, queue_length=queue_length)
        t.subscribe(callback)
        self._topics.append(t)
        return t

    def advertise(self, topic: str, msg_type: str):
        """A roslibpy Topic advertised for publishing."""
        import roslibpy

        t = roslibpy.Topic(self.ros, topic, msg_type)
        t.advertise()
        self._topics.append(t)
        return t

    def close(self) -> None:
        """Unsubscribe, close the websocket, stop roslibpy's reconnection attempts."""
        if self.ros is None:
            return
        self._closing = True
        ros, self.ros = self.ros, None
        if self.lost is None:
            for t in self._topics:
                try:
                    t.unsubscribe() if t.is_subscribed else t.unadvertise()
                except Exception:  # the link may be half gone; closing goes on
                    pass
            try:
                ros.close(timeout=2.0)
            except Exception as exc:
                log.debug("%s: rosbridge close: %s", self.who, exc)
        self._topics = []
        _stop_retrying(ros)

    def _probe(self) -> None:
        """Fail fast, naming the reason, when nothing listens at the address."""
        try:
            with socket.create_connection((self.cfg.host, self.cfg.port), timeout=self.cfg.connect_timeout_s):
                pass
        except OSError as exc:
            reason = "timed out" if isinstance(exc, socket.timeout) else (exc.strerror or str(exc))
            raise RosbridgeUnreachableError(f"{self.who}: unreachable rosbridge at {self.cfg.url}: {reason}; "
                                            f"hint: {HINT}") from exc

    def _on_close(self, *args) -> None:
        if not self._closing and self.lost is None:
            self.lost = f"{self.who}: rosbridge link to {self.cfg.url} lost"
            if self.ros is not None:
                _stop_retrying(self.ros)


def _stop_retrying(ros) -> None:
    """Stop roslibpy's reconnect loop (twisted: ReconnectingClientFactory; asyncio: its own)."""
    factory = ros.factory
    if hasattr(factory, "stopTrying"):
        from twisted.internet import reactor

        def stop():
            factory.stopTrying()
            connector = getattr(factory, "connector", None)
            if connector is not None and connector.state != "connected":
                connector.stopConnecting() if connector.state == "connecting" else None
        reactor.callFromThread(stop)
    elif hasattr(factory, "_stop"):
        factory._stop = True
