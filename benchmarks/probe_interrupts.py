"""Send Ctrl-C (or SIGTERM) to a command at moments spread over its life; print what it did.

    python benchmarks/probe_interrupts.py --copy RUN_DIR --at 0.3,0.9,1.5,2.1 --repeat 3 \\
        -- tactile-analyze run={dir} analysis.progress=false
    python benchmarks/probe_interrupts.py --at 0.3,2,5,8 -- tactile-run hydra.run.dir={dir} progress=false

Each try runs the command in a fresh directory (``{dir}`` in its arguments; a copy of
``--copy`` if given), sends the signal ``t`` seconds after the start, and prints one JSON
line: the exit status, the last line of stderr, and the problems found. A problem is an exit
status other than 0 (done) or 3 (interrupted), a traceback or an "Exception ignored" in its
output, or a ``.analysis-*`` staging directory left behind. The last line sums them up. This
is how the holes in ``docs/reliability.md`` items 22–25 and 27 were found.
"""

from __future__ import annotations

import argparse
import json
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def probe(command: list[str], at: float, sig: int, copy: Path | None) -> dict:
    with tempfile.TemporaryDirectory(prefix="probe-") as tmp:
        work = Path(tmp) / "dir"
        if copy is not None:
            shutil.copytree(copy, work)
        args = [a.replace("{dir}", str(work)) for a in command]
        proc = subprocess.Popen(args, cwd=tmp, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(at)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=600)
        problems = []
        if proc.returncode not in (0, 3):
            problems.append(f"exit status {proc.returncode}")
        if "Traceback" in out + err or "Exception ignored" in out + err:
            problems.append("traceback")
        if work.exists() and any(work.rglob(".analysis-*")):
            problems.append("staging directory left")
        last = err.strip().splitlines()[-1] if err.strip() else ""
        return {"at_s": at, "exit": proc.returncode, "stderr_last_line": last[:200], "problems": problems}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--at", required=True, help="seconds after the start, comma-separated")
    parser.add_argument("--repeat", type=int, default=1, help="tries at each moment (default 1)")
    parser.add_argument("--signal", choices=["INT", "TERM"], default="INT")
    parser.add_argument("--copy", type=Path, help="a directory copied to {dir} before each try")
    parser.add_argument("command", nargs="+", help="the command, after --")
    args = parser.parse_args()
    sig = signal.SIGINT if args.signal == "INT" else signal.SIGTERM
    moments = [float(t) for t in args.at.split(",")]
    bad = 0
    for _ in range(args.repeat):
        for at in moments:
            row = probe(args.command, at, sig, args.copy)
            bad += bool(row["problems"])
            print(json.dumps(row), flush=True)
    print(json.dumps({"bench": "interrupt_probe", "tries": args.repeat * len(moments), "with_problems": bad}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
