"""A rosbridge v2 server emulating the Shadow Hand's ROS stack, on a websocket (autobahn/asyncio).

Run as a process (``python -m tactile_flow.hardware.emulators.rosbridge_server --port 0``); it prints
``READY url=ws://127.0.0.1:<port>`` once listening. It speaks the JSON operations a
roslibpy client uses — ``advertise``/``unadvertise``, ``publish``, ``subscribe``/
``unsubscribe``, ``call_service`` (``/rosapi/topics``, ``/rosapi/get_time``) — and:

- publishes ``/rh/tactile`` (``sr_robot_msgs/BiotacAll``) at 100 Hz: counts from the
  simulator's sensor model (calibrated on a real Shadow Hand recording), resting or — with
  ``--world-dir`` — pressed by the emulated world (:mod:`.touch`: the board under the
  emulated arm, the bottle in the hand), ``header.seq`` counting up, wall-clock stamps;
  fingers given with ``--unconnected`` read pdc = -22072 and zeros, as Shadow's driver
  publishes them;
- publishes ``/joint_states`` (``sensor_msgs/JointState``) at 100 Hz (with the world, the
  grasp fingers stop on the held bottle);
- follows ``/rh_trajectory_controller/command`` (``trajectory_msgs/JointTrajectory``):
  each named joint moves from where it is to the last point's position, reaching it at
  that point's ``time_from_start`` (linear in time); with the world the trajectory is shared
  (``<world dir>/hand``) so the serial BioTac emulator's world grips as this one does.

Control lines on stdin (each answered by one ``OK <json>`` or ``ERR <reason>`` line):
``pause``/``resume`` publishing (a hung driver), ``stats`` (with the world's bottle and the
monotonic receipt time of every hand command), ``frames A B`` (the monotonic times the
BiotacAll messages ``A``..``B`` were sent), and the faults a real link can show:
``corrupt MODE N`` (the next N ``BiotacAll`` messages malformed: ``garbage``, a
``tactiles`` field that is not a list; ``overflow``, an electrode at 70000, beyond any 16-bit
count; ``missing``, the first finger without its ``pdc``), ``disconnect TOPIC`` (close the
websocket of every client subscribed to ``TOPIC``: the link of that one device lost).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import threading
import time

import numpy as np

from ..biotac import FINGERS
from ..hand import JOINT_NAMES
from .process import EmulatorProcess, emulated_sensor, sensor_model_config
from .touch import frame_times, trajectory_positions

CATCH_UP_S = 1.0       # a late loop sends the frames it missed up to this far back (s)

UNCONNECTED = {"pac0": 0, "pac1": 0, "pac": [], "pdc": -22072, "tac": 32570, "tdc": 0, "electrodes": [0] * 24}
"""A port without a sensor (its ``electrodes`` as long as the model's: :meth:`BiotacSource.message`)."""
CORRUPTIONS = ("garbage", "overflow", "missing")


def corrupted(msg: dict, mode: str) -> dict:
    """``msg`` (a BiotacAll) made malformed as ``mode`` says (see the module doc)."""
    if mode == "garbage":
        return {**msg, "tactiles": "garbage"}
    tactiles = [dict(t) for t in msg["tactiles"]]
    if mode == "overflow":
        tactiles[0]["electrodes"] = [*tactiles[0]["electrodes"][:6], 70000, *tactiles[0]["electrodes"][7:]]
    else:
        tactiles[0].pop("pdc")
    return {**msg, "tactiles": tactiles}


TOPIC_TYPES = {"/rh/tactile": "sr_robot_msgs/BiotacAll", "/joint_states": "sensor_msgs/JointState",
               "/rh_trajectory_controller/command": "trajectory_msgs/JointTrajectory"}


def ros_time(t: float) -> dict:
    secs = int(t)
    return {"secs": secs, "nsecs": int((t - secs) * 1e9)}


class HandModel:
    """Joint positions following linear-in-time segments toward commanded targets."""

    def __init__(self, shared=None):
        n = len(JOINT_NAMES)
        self.start_q = np.zeros(n)
        self.goal_q = np.zeros(n)
        self.t_start = np.zeros(n)
        self.t_end = np.zeros(n)
        self.commands = 0
        self.received: list[float] = []       # monotonic receipt time of each command (s)
        self.shared = shared                  # a touch.HandFile the emulated world reads, or None
        self._share()

    def positions(self, t: float) -> np.ndarray:
        """Commanded angles (24,) rad at monotonic time ``t``."""
        return trajectory_positions(self.start_q, self.goal_q, self.t_start, self.t_end, t)

    def _share(self) -> None:
        if self.shared is not None:
            self.shared.write(self.start_q, self.goal_q, self.t_start, self.t_end)

    def command(self, msg: dict, t: float) -> None:
        points = msg.get("points") or []
        if not points:
            return
        last = points[-1]
        d = last.get("time_from_start", {})
        duration = float(d.get("secs", d.get("sec", 0))) + 1e-9 * float(d.get("nsecs", d.get("nanosec", 0)))
        q = self.positions(t)
        for name, goal in zip(msg.get("joint_names", []), last.get("positions", [])):
            if name in JOINT_NAMES:
                i = JOINT_NAMES.index(name)
                self.start_q[i], self.goal_q[i] = q[i], float(goal)
                self.t_start[i], self.t_end[i] = t, t + duration
        self._share()
        self.commands += 1
        self.received.append(t)


class BiotacSource:
    """BiotacAll messages from the simulator's calibrated sensor model: resting counts, or
    pressed by the emulated world when ``touch`` (:class:`~.touch.EmulatedWorld`) is given.
    ``sent[k]`` is the monotonic time message ``k + 1`` was handed to the websocket (s)."""

    def __init__(self, unconnected=(), seed: int = 0, rate_hz: float = 100.0, touch=None, sensor=None,
                 model_config=None):
        from ..sim.sensor import BiotacModel, SensorInputs

        self.connected = [f for f in FINGERS if f not in unconnected]
        F = len(self.connected)
        self.model = BiotacModel(self.connected, model_config or sensor_model_config(),
                                 np.random.default_rng(seed), 1.0 / rate_hz, sensor)
        self.inputs = SensorInputs(np.zeros((F, self.model.N)), np.zeros(F), np.zeros(F), np.zeros(F))
        self.touch = touch
        self.seq = 0
        self.t0 = time.monotonic()
        self.sent: list[float] = []

    def message(self, wall: float, now: float | None = None) -> dict:
        """The BiotacAll message of the frame sampled at monotonic ``now`` (default: now),
        stamped ``wall`` (s since the epoch)."""
        now = time.monotonic() if now is None else now
        t = now - self.t0
        if self.touch is not None:
            self.inputs = self.touch.inputs(now)
        e, pdc, tdc, tac, pac = self.model.frame(t, self.inputs)
        self.seq += 1
        tactiles = []
        for f in FINGERS:
            if f not in self.connected:
                tactiles.append({**UNCONNECTED, "electrodes": [0] * self.model.N})
                continue
            k = self.connected.index(f)
            p = [int(x) for x in pac[k]]
            tactiles.append({"pac0": p[0], "pac1": p[1], "pac": p, "pdc": int(pdc[k]), "tac": int(tac[k]),
                             "tdc": int(tdc[k]), "electrodes": [int(x) for x in e[k]]})
        return {"header": {"seq": self.seq, "stamp": ros_time(wall), "frame_id": "rh_distal"}, "tactiles": tactiles}


class Bridge:
    """Server state: clients and their subscriptions, the hand, the BioTacs, counters."""

    def __init__(self, unconnected=(), seed: int = 0, rate_hz: float = 100.0, touch=None, sensor=None,
                 model_config=None):
        self.clients: set = set()
        self.hand = HandModel(None if touch is None else touch.hand_writer())
        self.biotacs = BiotacSource(unconnected, seed, rate_hz, touch, sensor, model_config)
        self.world = touch
        self.rate_hz = rate_hz
        self.paused = False
        self.published = {"/rh/tactile": 0, "/joint_states": 0}
        self.js_seq = 0
        self.corrupt_mode, self.corrupt_left, self.corrupted = None, 0, 0

    def handle(self, client, msg: dict) -> None:
        op = msg.get("op")
        topic = msg.get("topic")
        if op == "subscribe":
            client.subscriptions.add(topic)
        elif op == "unsubscribe":
            client.subscriptions.discard(topic)
        elif op == "publish" and topic == "/rh_trajectory_controller/command":
            self.hand.command(msg.get("msg", {}), time.monotonic())
        elif op == "call_service":
            client.send_json(self.service(msg))
        # advertise / unadvertise / other publishes need no answer from a rosbridge server

    def service(self, msg: dict) -> dict:
        name = msg.get("service")
        reply = {"op": "service_response", "service": name, "id": msg.get("id"), "result": True}
        if name == "/rosapi/topics":
            reply["values"] = {"topics": list(TOPIC_TYPES), "types": list(TOPIC_TYPES.values())}
        elif name == "/rosapi/get_time":
            reply["values"] = {"time": ros_time(time.time())}
        else:
            reply.update(result=False, values=f"service {name} does not exist (emulated rosbridge)")
        return reply

    def tick(self, now: float | None = None) -> None:
        """Publish the frame and the joint state sampled at monotonic ``now`` (default: now;
        a late loop passes the periods it missed, which go out late but dated)."""
        if self.paused or not self.clients:
            return
        mono = time.monotonic()
        now = mono if now is None else now
        wall = time.time() - (mono - now)
        msg = self.biotacs.message(wall, now)
        if self.corrupt_left > 0:
            msg = corrupted(msg, self.corrupt_mode)
            self.corrupt_left -= 1
            self.corrupted += 1
        self.biotacs.sent.append(time.monotonic())
        self._publish("/rh/tactile", msg)
        self.js_seq += 1
        q = self.hand.positions(now)
        if self.world is not None:
            q = self.world.measured_positions(q)
        self._publish("/joint_states", {"header": {"seq": self.js_seq, "stamp": ros_time(wall), "frame_id": ""},
                                        "name": list(JOINT_NAMES), "position": q.tolist(),
                                        "velocity": [0.0] * len(q), "effort": [0.0] * len(q)})

    def _publish(self, topic: str, msg: dict) -> None:
        payload = None
        for c in list(self.clients):
            if topic in c.subscriptions:
                payload = payload or json.dumps({"op": "publish", "topic": topic, "msg": msg}).encode()
                c.sendMessage(payload, isBinary=False)
        self.published[topic] += 1

    def control(self, line: str) -> str:
        cmd = line.strip()
        if cmd in ("pause", "resume"):
            self.paused = cmd == "pause"
            return f"OK {json.dumps({'paused': self.paused})}"
        words = cmd.split()
        if words[:1] == ["corrupt"]:
            if len(words) != 3 or words[1] not in CORRUPTIONS or not words[2].isdigit():
                return f"ERR expected corrupt {'|'.join(CORRUPTIONS)} N"
            self.corrupt_mode, self.corrupt_left = words[1], int(words[2])
            return f"OK {json.dumps({'corrupt': words[1], 'frames': int(words[2])})}"
        if words[:1] == ["disconnect"] and len(words) == 2:
            dropped = [c for c in list(self.clients) if words[1] in c.subscriptions]
            for c in dropped:
                self.clients.discard(c)
                c.dropConnection(abort=True)          # as a cable pulled: no closing handshake
            return f"OK {json.dumps({'disconnected': len(dropped)})}"
        if cmd == "stats":
            return "OK " + json.dumps({"published": self.published, "clients": len(self.clients),
                                       "corrupted": self.corrupted,
                                       "hand_commands": self.hand.commands, "biotac_seq": self.biotacs.seq,
                                       "hand_command_times": self.hand.received,
                                       "positions": dict(zip(JOINT_NAMES, self.hand.positions(time.monotonic()).round(4).tolist())),
                                       "world": None if self.world is None else self.world.state()})
        if len(words) == 3 and words[0] == "frames" and all(w.isdigit() for w in words[1:]):
            return "OK " + json.dumps(frame_times(self.biotacs.sent, int(words[1]), int(words[2])))
        return (f"ERR unknown command {cmd!r}; expected pause, resume, stats, frames A B, corrupt MODE N, "
                f"disconnect TOPIC")


def make_protocol(bridge: Bridge):
    from autobahn.asyncio.websocket import WebSocketServerProtocol

    class RosbridgeProtocol(WebSocketServerProtocol):
        def onOpen(self):
            self.subscriptions = set()
            bridge.clients.add(self)

        def onMessage(self, payload, isBinary):
            try:
                msg = json.loads(payload)
            except ValueError:
                return
            bridge.handle(self, msg)

        def onClose(self, wasClean, code, reason):
            bridge.clients.discard(self)

        def send_json(self, msg: dict) -> None:
            self.sendMessage(json.dumps(msg).encode(), isBinary=False)

    return RosbridgeProtocol


async def serve(host: str, port: int, bridge: Bridge) -> None:
    from autobahn.asyncio.websocket import WebSocketServerFactory

    factory = WebSocketServerFactory(f"ws://{host}:{port or 9090}")   # the URL only names the server
    factory.protocol = make_protocol(bridge)
    loop = asyncio.get_running_loop()
    server = await loop.create_server(factory, host, port)
    actual = server.sockets[0].getsockname()[1]
    done = asyncio.Event()

    def read_stdin():                       # control channel; EOF (parent gone) stops the server
        for line in sys.stdin:
            reply = asyncio.run_coroutine_threadsafe(_control(bridge, line), loop).result()
            print(reply, flush=True)
        loop.call_soon_threadsafe(done.set)

    threading.Thread(target=read_stdin, daemon=True).start()
    print(f"READY url=ws://{host}:{actual}", flush=True)
    period = 1.0 / bridge.rate_hz
    t_next = loop.time()                    # asyncio's clock is time.monotonic
    while not done.is_set():
        bridge.tick(t_next)
        # the sensors sample on their own clock: a late loop sends the periods it missed, dated
        # (as a driver behind a stalled link would), up to CATCH_UP_S; beyond, they are skipped
        t_next = max(t_next + period, loop.time() - CATCH_UP_S)
        await asyncio.sleep(max(0.0, t_next - loop.time()))
    server.close()


async def _control(bridge: Bridge, line: str) -> str:
    return bridge.control(line)


class RosbridgeEmulator(EmulatorProcess):
    """The rosbridge emulator as a child process; ``url`` is where it listens.

        with RosbridgeEmulator() as emu:              # port 0: a free port
            ShadowHand(ShadowHandConfig(RosbridgeConfig(emu.url)))
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0, seed: int = 0, unconnected=(),
                 rate_hz: float = 100.0, world_dir: str | None = None, surface: str = "straws",
                 sensor: str = "biotac_sp", shear_kohm_per_n: float | None = None):
        args = ["--host", host, "--port", port, "--seed", seed, "--rate", rate_hz, "--sensor", sensor]
        if shear_kohm_per_n is not None:
            args += ["--shear-kohm-per-n", shear_kohm_per_n]
        if unconnected:
            args += ["--unconnected", ",".join(unconnected)]
        if world_dir:
            args += ["--world-dir", world_dir, "--surface", surface]
        super().__init__("tactile_flow.hardware.emulators.rosbridge_server", args)

    @property
    def url(self) -> str:
        return self.ready["url"]

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stats(self) -> dict:
        return json.loads(self.command("stats"))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="rosbridge v2 emulator of the Shadow Hand and its BioTacs")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=9090, help="0: any free port (printed on the READY line)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--rate", type=float, default=100.0, help="BiotacAll and JointState rate (Hz)")
    p.add_argument("--unconnected", default="", help="fingers without a sensor, e.g. rf,lf")
    p.add_argument("--world-dir", default=None,
                   help="the emulated world's shared files (touch.py): the BioTacs press on the board under the "
                        "emulated arm and hold the bottle in the hand")
    p.add_argument("--surface", default="straws", help="the board pressed on (conf/surface/NAME.yaml; none: no board)")
    p.add_argument("--sensor", default="biotac_sp", help="the BioTacs' sensor model: a name (conf/sensor/) or a .yaml")
    p.add_argument("--shear-kohm-per-n", type=float, default=None,
                   help="the BioTacs' shear response, kΩ per N (hardware.sensor.shear_kohm_per_n; default: the simulator's)")
    a = p.parse_args(argv)
    unconnected = [f for f in a.unconnected.split(",") if f]
    if any(f not in FINGERS for f in unconnected):
        p.error(f"--unconnected: expected names of {FINGERS}, got {unconnected}")
    sensor = emulated_sensor(a.sensor, p)
    touch = None
    sensor = emulated_sensor(a.sensor, p)
    touch = None
    if a.world_dir:
        from .touch import EmulatedWorld
        touch = EmulatedWorld(a.world_dir, None if a.surface == "none" else a.surface,
                              [f for f in FINGERS if f not in unconnected], sensor)
    bridge = Bridge(unconnected, a.seed, a.rate, touch, sensor, sensor_model_config(a.shear_kohm_per_n, p))
    try:
        asyncio.run(serve(a.host, a.port, bridge))
    except OSError as exc:
        print(f"ERROR cannot listen on {a.host}:{a.port}: {exc}", flush=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
