"""Run ``tactile-run`` printing the simulated clock every 5 ms of wall time (``t <seconds>``).

    python benchmarks/clock_probe.py progress=false analyze=false ...

A measuring aid for what a kill loses (``bench_kill.py``, ``tests/test_kill_loss.py``):
the last line printed before a SIGKILL says how far the run had got in its own time. The
run itself is the real one; only the clock is watched from a thread.
"""

import threading
import time

import tactile_flow.hardware.sim.clock as sim_clock

clocks = []
_init = sim_clock.SimClock.__init__


def _record(self, *args, **kwargs):
    _init(self, *args, **kwargs)
    clocks.append(self)


def _report():
    while True:
        if clocks:
            print(f"t {clocks[-1].now():.4f}", flush=True)
        time.sleep(0.005)


if __name__ == "__main__":
    sim_clock.SimClock.__init__ = _record
    threading.Thread(target=_report, daemon=True).start()
    from tactile_flow.protocols.cli import main
    main()
