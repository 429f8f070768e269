"""Where a dataset analysis's CPU goes, stage by stage: CPU seconds per record.

    python benchmarks/bench_dataset.py --records 300 --no-figures --dir /tmp/bd     # makes /tmp/bd/dataset_300
    tactile-import source=/tmp/bd/dataset_300 out=/tmp/bd/stages rate_hz=100
    python benchmarks/bench_analysis_stages.py run=/tmp/bd/stages analysis.figures=false

Runs ``tactile-analyze`` (its own overrides: ``run=DIR`` and any other) in this process with
one worker (``workers=1 analysis.workers=1``) and times the stages of each record's analysis
by the process's CPU clock (``time.process_time``: what other processes' load does not
count, unlike wall time; a profiler's own cost is not added either): loading the run, the
tactile flow, the slip estimate, writing the packed ``analysis.zarr.zip``, the commit, the
catalogue. Prints one JSON line per stage: ``{"stage", "cpu_s_per_record", "calls"}``
(inclusive: a stage's time holds its inner stages'), then the command's total CPU per record,
start-up included. An analysis already made with the same code and config is reused, not
timed: analyse a fresh import.
"""

from __future__ import annotations

import collections
import importlib
import json
import sys
import time

#: (module under tactile_flow, function) timed where it is looked up when called
STAGES = [
    ("analysis.run", "analyze_run"), ("analysis.run", "peek_sensor"), ("analysis.run", "load_run"),
    ("analysis.run", "analyse"), ("analysis.flows", "compute"), ("analysis.slip", "estimate"),
    ("analysis.pipeline", "prepare"), ("analysis.results", "to_tree"), ("analysis.results", "dumps"),
    ("runstore.labelled", "write_tree"), ("runstore.labelled", "store_members"), ("runstore.packed", "write_zip"),
    ("runstore.analyses", "commit"), ("analysis.run", "register_quietly"),
]


def main(argv: list[str]) -> int:
    cpu = collections.defaultdict(float)
    calls = collections.Counter()
    for module, name in STAGES:
        m = importlib.import_module(f"tactile_flow.{module}")
        f = getattr(m, name)

        def timed(*a, _f=f, _label=f"{module}.{name}", **k):
            t = time.process_time()
            try:
                return _f(*a, **k)
            finally:
                cpu[_label] += time.process_time() - t
                calls[_label] += 1
        setattr(m, name, timed)
    from tactile_flow.analysis.cli import main as analyze
    sys.argv = ["tactile-analyze", *argv, "workers=1", "analysis.workers=1", "analysis.progress=false"]
    try:
        analyze()
    except SystemExit as exc:
        if exc.code not in (0, None):
            return int(exc.code) if isinstance(exc.code, int) else 1
    n = calls["analysis.run.analyze_run"] or 1
    for label, s in sorted(cpu.items(), key=lambda kv: -kv[1]):
        print(json.dumps({"stage": label, "cpu_s_per_record": round(s / n, 4), "calls": calls[label]}))
    print(json.dumps({"records": n, "command_cpu_s_per_record": round(time.process_time() / n, 4)}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
