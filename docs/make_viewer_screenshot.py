"""A screenshot of the web viewer on a recorded run, taken with headless Chromium: docs/figures/viewer.png.

    python docs/make_viewer_screenshot.py                      # a fresh straws sweep (tactile-run), at 9.9 s
    python docs/make_viewer_screenshot.py RUN_DIR --time 20.3  # any run, at any time (s since run start)

Needs the ``[view]`` extra and Debian's ``chromium`` (``apt-get install -y chromium``). Steps:
``tactile-view RUN_DIR --save`` writes the recording; ``rerun --serve-web`` serves it with the web
viewer on two free local ports; Chromium (headless, no GPU: WebGL through SwiftShader, the
software renderer, which the viewer flags as "Software rasterizer") opens the page, driven over
its DevTools pipe (stdlib only); once the recording has loaded, the viewer's time cursor is set
(the web viewer's ``viewer_control`` call with a ``SetTimeCursor`` request of Rerun 0.41's
``viewer_control.proto``, hand-encoded below: paused at ``--time``), and the page is captured.
Everything started here is stopped here.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from urllib.parse import quote

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run",
                  "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                  "--window-size=1600,1000", "--remote-debugging-pipe"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def fresh_run(work: Path) -> Path:
    """A straws sweep on the simulated lab, analysed (its segments are in the viewer)."""
    subprocess.run([str(Path(sys.executable).parent / "tactile-run"), "progress=false", "analysis.figures=false",
                    f"hydra.run.dir={work / 'run'}"], check=True, cwd=work, capture_output=True)
    return work / "run"


class DevTools:
    """Chromium's DevTools protocol over ``--remote-debugging-pipe`` (fds 3 and 4, NUL-separated JSON)."""

    def __init__(self, user_data_dir: Path):
        to_chrome, self._w = os.pipe()
        self._r, from_chrome = os.pipe()

        def fds():
            a, b = os.dup(to_chrome), os.dup(from_chrome)
            os.dup2(a, 3)
            os.dup2(b, 4)
        self.proc = subprocess.Popen([shutil.which("chromium") or "chromium", *CHROMIUM_FLAGS,
                                      f"--user-data-dir={user_data_dir}", "about:blank"],
                                     preexec_fn=fds, close_fds=False, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        os.close(to_chrome)
        os.close(from_chrome)
        self._buf, self._id, self.session = b"", 0, None

    def call(self, method: str, params=None, session: bool = True) -> dict:
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if session and self.session:
            msg["sessionId"] = self.session
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        while True:
            while b"\0" not in self._buf:
                chunk = os.read(self._r, 1 << 20)
                if not chunk:
                    raise RuntimeError("chromium closed its DevTools pipe")
                self._buf += chunk
            raw, self._buf = self._buf.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]

    def open(self, url: str) -> None:
        target = self.call("Target.createTarget", {"url": url}, session=False)["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True},
                                 session=False)["sessionId"]

    def evaluate(self, expression: str):
        return self.call("Runtime.evaluate", {"expression": expression, "awaitPromise": True})["result"].get("value")

    def close(self) -> None:
        try:
            self.call("Browser.close", session=False)
            self.proc.wait(10)
        except (RuntimeError, OSError, subprocess.TimeoutExpired):
            self.proc.kill()


def set_time_request(timeline: str, seconds: float) -> bytes:
    """An encoded ``ViewerControlRequest{set_time_cursor: SetTimeCursorRequest{timeline, time,
    play_state: PAUSED}}`` (field numbers of Rerun 0.41's viewer_control.proto: 6; 2, 3, 5)."""
    def varint(n: int) -> bytes:
        out = bytearray()
        while True:
            out.append((n & 0x7F) | (0x80 if n > 0x7F else 0))
            n >>= 7
            if not n:
                return bytes(out)

    def message(field: int, payload: bytes) -> bytes:
        return varint(field << 3 | 2) + varint(len(payload)) + payload
    nanos = int(round(seconds * 1e9))
    inner = message(2, message(1, timeline.encode())) + message(3, varint(1 << 3) + varint(nanos)) + varint(5 << 3) + b"\x01"
    return message(6, inner)


def screenshot(rrd: Path, out: Path, seconds: float, timeout_s: float = 180.0) -> None:
    import rerun_cli                      # the rerun binary itself, so that stopping it stops the server
    grpc, web = free_port(), free_port()
    server = subprocess.Popen([str(Path(rerun_cli.__file__).parent / "rerun"), "--serve-web", "--bind", "127.0.0.1", "--port",
                               str(grpc), "--web-viewer-port", str(web), str(rrd)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    profile = Path(tempfile.mkdtemp(prefix="chromium-profile-"))
    chrome = None
    try:
        time.sleep(3)
        chrome = DevTools(profile)
        chrome.open(f"http://127.0.0.1:{web}/?url={quote(f'rerun+http://127.0.0.1:{grpc}/proxy', safe='')}")
        request = list(set_time_request("time", seconds))
        deadline = time.monotonic() + timeout_s
        while True:                       # until the app is up and the recording's timeline has arrived
            answer = chrome.evaluate("window._handle ? window._handle.viewer_control(new Uint8Array(%s))"
                                     ".then(() => 'ok', e => 'error: ' + e) : 'loading'" % request)
            if answer == "ok":
                break
            if time.monotonic() > deadline:
                raise RuntimeError(f"the web viewer did not load the recording within {timeout_s:.0f} s ({answer})")
            time.sleep(2)
        time.sleep(8)                     # let the software renderer paint every view
        png = chrome.call("Page.captureScreenshot", {"format": "png"})["data"]
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_bytes(base64.b64decode(png))
    finally:
        if chrome is not None:
            chrome.close()
        server.terminate()
        server.wait(10)
        shutil.rmtree(profile, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", nargs="?", help="a run directory (default: a fresh straws sweep)")
    ap.add_argument("--time", type=float, default=9.9, help="time cursor, s since run start (default 9.9: "
                                                            "the second straw of the default sweep)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "figures" / "viewer.png"))
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="viewer-shot-") as tmp:
        run_dir = Path(args.run_dir) if args.run_dir else fresh_run(Path(tmp))
        rrd = Path(tmp) / "run.rrd"
        subprocess.run([str(Path(sys.executable).parent / "tactile-view"), str(run_dir), "--save", str(rrd)],
                       check=True)
        screenshot(rrd, Path(args.out), args.time)
    print(f"{args.out}: the web viewer on {run_dir} at {args.time:g} s")


if __name__ == "__main__":
    main()
