"""A sweep never hides a job that failed or was refused (issue 34, item 8): its count is of
jobs, not of the runs they left, and every job that did not succeed is named with its error, on
the console and in ``summary.md``."""

import json
import subprocess
import sys

import pytest

from tactile_flow.cliapp import jobresults

RUN = [sys.executable, "-c", "from tactile_flow.protocols.entry import main; main()"]


def test_counts_and_failures_name_every_job():
    results = [{"job": 0, "code": 0, "overrides": ["x=1"]},
               {"job": 1, "code": 2, "overrides": ["x=2"], "error": "error: x: got 2; expected 1"},
               {"job": 2, "code": 3, "overrides": ["x=3"], "error": "run d: aborted (interlock tcp_force)"},
               {"job": 3, "code": None, "overrides": ["x=4"], "pid": 7, "host": "h"}]
    assert jobresults.counts(results) == "4 jobs: 1 succeeded, 1 refused (bad input), 1 aborted, 1 failed"
    lines = jobresults.failures(results)
    assert lines[0] == "job 1 (x=2): refused (bad input): error: x: got 2; expected 1"
    assert lines[1] == "job 2 (x=3): aborted: run d: aborted (interlock tcp_force)"
    assert lines[2].startswith("job 3 (x=4): no result") and len(lines) == 3


@pytest.mark.slow
def test_a_refused_job_in_the_middle_of_a_sweep_is_counted_and_named(tmp_path):
    proc = subprocess.run([*RUN, "-m", "protocol.sweep_speed=10,900,20", "analyze=false", "progress=false",
                           "hydra.sweep.dir=sweep"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    named = [line for line in proc.stderr.splitlines() if line.startswith("job 1 ")]
    assert named == ["job 1 (protocol.sweep_speed=900 analyze=False progress=False): refused (bad input): error: "
                     "protocol.steps[3].sweep.speed: 900.0 mm/s exceeds the arm's limit hardware.arm.max_speed_m_s=0.25"]
    assert "sweep sweep: 3 jobs: 2 succeeded, 1 refused (bad input); summary.md, summary.csv" in proc.stdout
    import csv
    with open(tmp_path / "sweep" / "summary.csv") as f:
        table = list(csv.DictReader(f))
    assert [(r["protocol.sweep_speed"], r["status"]) for r in table] == [
        ("10", "success"), ("900", "refused (bad input)"), ("20", "success")]
    assert "900.0 mm/s exceeds" in table[1]["error"]
    (first,) = (tmp_path / "sweep").glob("0_*/run.json")
    assert json.loads(first.read_text())["status"] == "success"
