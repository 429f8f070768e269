"""Rerun's servers, on the loopback interface unless asked otherwise.

Rerun's Python calls that serve a viewer (``rr.serve_grpc``, ``rr.serve_web_viewer``,
``rr.spawn``) listen on every network interface (0.0.0.0) and take no address: anyone who can
reach the machine could watch a run. The servers here are Rerun's own command-line viewer
(``python -m rerun``), started with ``--bind``: :data:`LOOPBACK` by default; another address
only when the user asks (``tactile-view --web --bind ADDR``), with a warning
(:func:`exposure_warning`). The recording is then sent to the server's gRPC port.
"""

from __future__ import annotations

import ipaddress
import os
import signal
import socket
import subprocess
import sys
import time
from urllib.parse import quote

LOOPBACK = "127.0.0.1"
NATIVE_PORT = 9876           # the native viewer's gRPC port (Rerun's default): one viewer reused by every run
START_TIMEOUT_S = 30.0       # Rerun's server binary starts in well under a second; a loaded machine, more


class ServeError(RuntimeError):
    """A server could not start (its port taken, a bad address); the message says which."""


def is_loopback(address: str) -> bool:
    """Whether ``address`` (an IP address or ``localhost``) reaches this machine only."""
    if address == "localhost":
        return True
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return False


def exposure_warning(address: str, ports) -> str | None:
    """The warning for serving on a non-loopback ``address`` (None on loopback)."""
    if is_loopback(address):
        return None
    where = "every network interface" if address in ("0.0.0.0", "::") else address
    return (f"warning: serving on {where} (ports {', '.join(map(str, ports))}): anyone who can reach this "
            f"machine can watch the run; the default, --bind {LOOPBACK}, serves this machine only")


def check_address(address: str) -> None:
    """Refuse an address that is not an IP address of this machine's kind (one line)."""
    if address == "localhost":
        return
    try:
        ipaddress.ip_address(address)
    except ValueError:
        raise ServeError(f"--bind {address}: expected an IP address (127.0.0.1, 0.0.0.0, ::, or one of this "
                         f"machine's)") from None


def free_port(address: str) -> int:
    """A TCP port free on ``address`` now (the kernel's choice)."""
    family = socket.AF_INET6 if ":" in address else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.bind((address, 0))
        return s.getsockname()[1]


def _client_host(address: str) -> str:
    """Where a client on this machine connects to a server bound to ``address``."""
    return LOOPBACK if address in ("0.0.0.0", "::", "localhost") else address


def _rerun(*args) -> list[str]:
    return [sys.executable, "-m", "rerun", *args]


class WebServer:
    """Rerun's web viewer and its gRPC proxy, in a child process bound to ``address``.

    ``with WebServer(LOOPBACK, 9091) as server: rec.connect_grpc(server.grpc_url)``; the browser
    opens :attr:`viewer_url`. The child is in its own session (a terminal's Ctrl-C reaches only
    this process, which stops it on exit)."""

    def __init__(self, address: str = LOOPBACK, web_port: int = 9091, grpc_port: int = 0):
        check_address(address)
        self.address, self.web_port = address, web_port
        self.grpc_port = grpc_port or free_port(address)
        self.process: subprocess.Popen | None = None

    @property
    def grpc_url(self) -> str:
        return f"rerun+http://{_client_host(self.address)}:{self.grpc_port}/proxy"

    @property
    def viewer_url(self) -> str:
        return f"http://{_client_host(self.address)}:{self.web_port}/?url={quote(self.grpc_url, safe='')}"

    def start(self) -> "WebServer":
        """Start the child and wait until both ports accept connections; :class:`ServeError`
        (the child's last line) if it exits or does not listen within :data:`START_TIMEOUT_S`."""
        self.process = subprocess.Popen(
            _rerun("--serve-web", "--bind", self.address, "--port", str(self.grpc_port),
                   "--web-viewer-port", str(self.web_port), "--hide-welcome-screen"),
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
            start_new_session=True, env={**os.environ, "RUST_LOG": "warn"})
        end = time.monotonic() + START_TIMEOUT_S
        host = _client_host(self.address)
        while not (_listening(host, self.grpc_port) and _listening(host, self.web_port)):
            if self.process.poll() is not None:
                self.stop()
                raise ServeError(self._why())
            if time.monotonic() > end:
                self.stop()
                raise ServeError(f"the web viewer did not start listening within {START_TIMEOUT_S:g} s")
            time.sleep(0.05)
        return self

    def _why(self) -> str:
        lines = [line.strip() for line in (self.process.stderr.read() if self.process.stderr else "").splitlines()
                 if line.strip()]
        if any("in use" in line.lower() for line in lines):
            return (f"--port {self.web_port} (or the gRPC port {self.grpc_port}) on {self.address} is in use; "
                    f"choose another with --port")
        return f"the web viewer could not start: {lines[-1] if lines else 'no message'}"

    def stop(self) -> None:
        """End the child (its whole session) and wait for it."""
        if self.process is None or self.process.poll() is not None:
            return
        try:
            os.killpg(self.process.pid, signal.SIGTERM)
            self.process.wait(timeout=5)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            try:
                os.killpg(self.process.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.process.wait()

    def __enter__(self) -> "WebServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def spawn_native_viewer(port: int, address: str = LOOPBACK) -> None:
    """Start Rerun's native viewer listening on ``address:port`` (detached, as ``rr.spawn``
    does), unless a viewer already listens there (it is reused)."""
    if _listening(_client_host(address), port):
        return
    subprocess.Popen(_rerun("--port", str(port), "--bind", address), stdin=subprocess.DEVNULL,
                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    end = time.monotonic() + START_TIMEOUT_S
    while not _listening(_client_host(address), port) and time.monotonic() < end:
        time.sleep(0.05)


def _listening(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=0.2):
            return True
    except OSError:
        return False
