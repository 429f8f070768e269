"""Figures addressed by their content (issue 36): the keys, and the earlier figures of a run
found by key. The re-analysis itself, on a real run: tests/test_analysis_runs.py."""

import json
import os
from functools import partial

import numpy as np
import pytest

from tactile_flow.analysis import figure_reuse, figures
from tactile_flow.runstore import analyses


def test_a_key_changes_with_any_input_and_only_with_them():
    inputs = {"time": np.arange(5.0), "segments": [("ff", "during", 1, 3)], "sensor": "biotac", "peaks": {"ff": None}}
    key = figure_reuse.figure_key("pressure.png", inputs)
    assert figure_reuse.figure_key("pressure.png", json.loads(json.dumps({**inputs, "time": list(range(5))}))) != key
    assert figure_reuse.figure_key("pressure.png", {**inputs, "time": np.arange(5.0)}) == key      # equal values
    assert figure_reuse.figure_key("taxels.png", inputs) != key                                   # another figure
    changed = [{**inputs, "time": np.arange(5.0) + 1e-12}, {**inputs, "time": np.arange(5, dtype=np.float32)},
               {**inputs, "time": np.arange(5.0).reshape(5, 1)}, {**inputs, "segments": [("ff", "during", 1, 4)]},
               {**inputs, "sensor": "biotac_sp"}, {**inputs, "peaks": {"ff": np.array([2])}}]
    assert len({figure_reuse.figure_key("pressure.png", c) for c in changed} | {key}) == len(changed) + 1


def test_a_key_changes_with_the_style(monkeypatch):
    import matplotlib as mpl
    key = figure_reuse.figure_key("pressure.png", {"x": 1})
    monkeypatch.setitem(mpl.rcParams, "lines.linewidth", 3.0)
    assert figure_reuse.figure_key("pressure.png", {"x": 1}) != key


def test_a_builder_without_its_inputs_listed_gets_no_key_and_an_unknown_type_none_either():
    def drawing(a):                                   # pragma: no cover - never called
        return None
    assert figures.job_key("other.png", partial(drawing, None)) is None
    with pytest.raises(TypeError):
        figure_reuse.figure_key("x.png", {"obj": object()})


def _analysis(run, name: str, keys: dict, files: dict, created: str) -> None:
    with analyses.staging(run) as staged:
        (staged / "figures").mkdir()
        for f, data in files.items():
            (staged / "figures" / f).write_bytes(data)
        analyses.commit(run, staged, name, {"analysis_id": name * 4, "created": created, "key": name,
                                            figure_reuse.KEY_FIELD: keys})


def test_earlier_figures_by_key_the_current_analysis_first_plain_files_only(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    _analysis(run, "a", {"pressure.png": "k1", "taxels.png": "k2", "gone.png": "k3", "../x.png": "k4"},
              {"pressure.png": b"a1", "taxels.png": b"a2", "x.png": b"a4"}, "2026-01-01")
    _analysis(run, "b", {"pressure.png": "k1", "flow_all.png": "k5"}, {"pressure.png": b"b1", "flow_all.png": b"b5"},
              "2026-01-02")
    os.symlink(run / "analyses" / "a" / "figures" / "taxels.png", run / "analyses" / "b" / "figures" / "link.png")
    meta = analyses.read_meta(run / "analyses" / "b")
    meta[figure_reuse.KEY_FIELD]["link.png"] = "k6"
    (run / "analyses" / "b" / analyses.META).write_text(json.dumps(meta))
    found = figure_reuse.earlier_figures(run)
    assert {k: p.read_bytes() for k, p in found.items()} == {"k1": b"b1", "k2": b"a2", "k5": b"b5"}
    analyses.make_current(run, "a")
    assert figure_reuse.earlier_figures(run)["k1"].read_bytes() == b"a1"
    figure_reuse.link(found["k5"], tmp_path / "flow_all.png")
    assert (tmp_path / "flow_all.png").stat().st_ino == found["k5"].stat().st_ino


def test_a_figures_folder_linked_out_of_the_run_is_never_read(tmp_path):
    """A planted ``analyses/<name>/figures`` link to another folder: its files are not the run's."""
    run, outside = tmp_path / "run", tmp_path / "outside"
    run.mkdir()
    outside.mkdir()
    (outside / "pressure.png").write_bytes(b"not ours")
    _analysis(run, "a", {"pressure.png": "k1"}, {}, "2026-01-01")
    figures = run / "analyses" / "a" / "figures"
    figures.rmdir()
    os.symlink(outside, figures)
    assert figure_reuse.earlier_figures(run) == {}
