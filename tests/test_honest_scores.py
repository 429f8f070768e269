"""Scores only for what the protocol declares and the truth contains; a score line names the
failed targets and by how much (issue 16, item 3)."""

import json
import subprocess
import sys

import pytest

from tactile_flow.analysis import labels as labelling
from tactile_flow.analysis.run import score_line


def test_generic_segments_carry_only_the_declared_labels():
    contacts = [(10, 40), (60, 80)]
    own = [s.label for s in labelling.generic_segments("ff", 100, contacts, ["approach", "contact", "lift"])]
    assert own == ["approach", "contact", "no_contact", "contact", "lift"]
    imported = [s.label for s in labelling.generic_segments("ff", 100, contacts, [])]
    assert imported == ["no_contact", "contact", "no_contact", "contact", "no_contact", "all"]
    assert "all" in [s.label for s in labelling.generic_segments("ff", 100, contacts, ["contact", "all"])]


def test_a_score_line_names_the_failed_targets_and_by_how_much():
    score = {"targets": {"direction_correct_fraction": {"target": 1.0, "value": 1.0, "met": True},
                         "width_error_mm_median": {"target": 1.0, "value": 1.2142, "met": False},
                         "boundary_error_mm_median": {"target": 0.75, "value": None, "met": False,
                                                      "reason": "not measured"}}}
    assert score_line(score) == ("targets NOT met (2 of 3): width_error_mm_median 1.21 (target ≤ 1); "
                                 "boundary_error_mm_median none (target ≤ 0.75, not measured)")
    score["targets"] = {"direction_correct_fraction": {"target": 1.0, "value": 1.0, "met": True}}
    assert score_line(score) == "targets met (1 of 1)"
    assert score_line({"targets": {}}).startswith("no target applies")


@pytest.mark.slow
def test_a_protocol_of_ones_own_is_scored_on_nothing_it_does_not_declare(tmp_path):
    """A press on a bump: no sweep target, no undeclared `all` segment, no 'NOT met'."""
    proc = subprocess.run(
        [sys.executable, "-c", "from tactile_flow.protocols.cli import main; main()", "surface=bump", "protocol.name=press_bump",
         "protocol.labels=[approach,contact,lift]",
         "protocol.steps=[{move_to: {at: feature_0, height: 5}}, {approach: {depth: 1.0}}, {hold: {duration: 1.0}},"
         " {lift: {height: 10}}]", "progress=false", "analysis.progress=false", "analysis.figures=false"],
        cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "no target applies" in proc.stdout and "NOT" not in proc.stdout, proc.stdout
    (run,) = (tmp_path / "outputs").glob("*/*_press_bump_*")
    labels = [s["label"] for s in json.loads((run / "analysis" / "summary.json").read_text())["segments"]]
    assert labels == ["approach", "contact", "lift"]
    score = json.loads((run / "analysis" / "score.json").read_text())
    assert score["targets"] == {} and score["all_targets_met"] is None
