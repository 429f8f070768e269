"""The analysis on real simulated runs (tactile-run in a subprocess, real zarr stores)."""

import json
import multiprocessing
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import xarray as xr

from tactile_flow.runstore import open_run
from tactile_flow.analysis.load import AnalysisInputError
from tactile_flow.runstore import analyses
from tactile_flow.analysis.run import analyze_run

BIN = Path(sys.executable).parent
FAST = {"progress": False, "figures": False}


def _tactile_run(cwd: Path, *overrides) -> Path:
    env = dict(os.environ, TACTILE_CACHE_DIR=os.environ.get("TACTILE_CACHE_DIR", str(cwd / "cache")))
    r = subprocess.run([str(BIN / "tactile-run"), "analyze=false", "progress=false", *overrides], cwd=cwd,
                       capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    (store,) = cwd.glob("outputs/*/*/run.zarr")
    return store


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = {}
    for proto in ("straws_sweep", "sticks_sweep", "pour_grasp"):
        d = tmp_path_factory.mktemp(proto)
        out[proto] = _tactile_run(d, f"protocol={proto}")
    return out


def _copy(store: Path, tmp: Path, name: str) -> Path:
    d = tmp / name
    d.mkdir()
    dst = d / "run.zarr"
    shutil.copytree(store, dst)
    return dst


@pytest.mark.parametrize("proto", ["straws_sweep", "sticks_sweep"])
def test_sweep_labels_estimates_and_score(runs, proto, tmp_path):
    store = _copy(runs[proto], tmp_path, proto)
    summary = analyze_run(store, FAST, console=lambda *a: None)
    labels = [s["label"] for s in summary["segments"]]
    assert labels == ["approach"] + ["before", "during", "after"] * 3 + ["lift"]
    score = json.loads((store.parent / "analysis" / "score.json").read_text())
    s = score["summary"]
    assert s["direction_correct_fraction"] == 1.0
    assert s["direction_world_error_deg_max"] < 30
    assert s["width_error_mm_median"] <= 1.0
    assert s["boundary_error_ms_median"] <= 50
    assert s["texture_angle_error_deg_median"] < 15
    tree = xr.open_datatree(f"zip::{store.parent / 'analysis' / 'analysis.zarr.zip'}", engine="zarr")
    assert tree["segments"].sizes["segment"] == 11
    assert set(tree["aggregates"]["view"].values) == {"bottom", "left", "right"}
    assert tree["estimates/crossings"]["width"].attrs["units"] == "mm"
    assert "headline" in summary and summary["headline"]["crossings"] == 3
    # the pattern's flow in the frames, px/frame: not a speed (docs/analysis.md), and not called one
    for c in summary["estimates"]["crossings"]:
        assert 0.01 < c["flow_px_per_frame"] < 1.0 and "flow_speed_mm_s" not in c


def test_pour_phases(runs, tmp_path):
    store = _copy(runs["pour_grasp"], tmp_path, "pour")
    summary = analyze_run(store, {**FAST, "views": ["bottom"]}, console=lambda *a: None)
    labels = {s["label"] for s in summary["segments"]}
    assert {"pour", "initial_slip", "rotation", "downward", "full_slip"} <= labels
    score = json.loads((store.parent / "analysis" / "score.json").read_text())
    for phase in ("pour", "initial_slip", "rotation", "downward", "full_slip"):
        assert abs(score["pour"][phase]["error_ms"]) < 150, (phase, score["pour"])
    assert abs(score["summary"]["slip_onset_error_ms"]) <= 100
    assert score["summary"]["boundary_error_ms_median"] <= 50
    # the thumb opposes the fingers: it is analysed too
    assert set(summary["estimates"]["pour"]["per_finger"]) == {"ff", "mf", "th"}


def test_the_same_analysis_is_reused_and_a_forced_one_is_identical_and_keeps_the_old(runs, tmp_path):
    """Same code, config and store: the kept analysis is reused (nothing computed); force=True
    computes it again, identical to the bit, and keeps the old one beside it."""
    store = _copy(runs["straws_sweep"], tmp_path, "idem")
    cfg = {"progress": False, "figures": True, "max_segment_figures": 2}
    first = analyze_run(store, cfg, console=lambda *a: None)
    a1 = open_run(store.parent / "analysis" / "analysis.zarr.zip").load()
    lines = []
    again = analyze_run(store, {**cfg, "workers": 1}, console=lines.append)      # workers: not in the key
    assert again["analysis_id"] == first["analysis_id"] and "reused" in lines[0], lines
    second = analyze_run(store, cfg, force=True, console=lambda *a: None)
    a2 = open_run(store.parent / "analysis" / "analysis.zarr.zip").load()
    for group in ("segments", "aggregates", "whole_run", "estimates/crossings"):
        xr.testing.assert_identical(a1[group].to_dataset(), a2[group].to_dataset())
    assert first["estimates"] == second["estimates"] and first["segments"] == second["segments"]
    assert first["provenance"]["input"]["sha256"] == second["provenance"]["input"]["sha256"]
    assert first["analysis_id"] != second["analysis_id"] and first["analysis"] == second["analysis"]
    kept = sorted(p.name for p in (store.parent / "analyses").iterdir() if not p.name.startswith("."))
    assert kept == sorted([first["analysis"], f"{first['analysis']}~{first['analysis_id'][:8]}"])
    history = [json.loads(x) for x in (store.parent / "analysis_history.jsonl").read_text().splitlines()]
    assert [h["event"] for h in history] == ["made", "reused", "replaced"]
    assert sorted(p.name for p in (store.parent / "analysis" / "figures").iterdir())[:2] == ["electrodes.png", "ellipsoid.png"]
    assert not list((store.parent / "analyses").glob(".staging-*"))


def test_not_a_run_store(tmp_path):
    (tmp_path / "junk").mkdir()
    with pytest.raises(AnalysisInputError, match="not a run store"):
        analyze_run(tmp_path / "junk", FAST)
    with pytest.raises(AnalysisInputError, match="no such file"):
        analyze_run(tmp_path / "nothing.zarr", FAST)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["junk"]


def _rewrite(store: Path, dst_dir: Path, edit) -> Path:
    tree = xr.open_datatree(str(store), engine="zarr").load()
    d = {node.path: node.to_dataset() for node in tree.subtree}
    d = edit(d)
    dst_dir.mkdir()
    out = dst_dir / "run.zarr"
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        xr.DataTree.from_dict(d).to_zarr(str(out), zarr_format=3, consolidated=True)
    return out


def test_missing_groups_no_contact_aborted_and_short_segments(runs, tmp_path):
    src = runs["straws_sweep"]

    def drop_arm_and_events(d):
        return {k: v for k, v in d.items() if not k.startswith(("/arm", "/events"))}
    store = _rewrite(src, tmp_path / "noarm", drop_arm_and_events)
    s = analyze_run(store, FAST, console=lambda *a: None)
    what = {x["what"] for x in s["skipped"]}
    assert {"group arm", "group events", "width"} <= what
    assert s["provenance"]["baseline"].startswith("no tare event")
    assert len(s["estimates"]["crossings"]) == 3                   # directions still estimated

    def before_contact(d):
        d["/biotac"] = d["/biotac"].isel(time=slice(0, 300))
        return d
    s = analyze_run(_rewrite(src, tmp_path / "nocontact", before_contact), FAST, console=lambda *a: None)
    assert s["headline"]["status"] == "no_contact" and s["segments"] == []
    assert any("no finger in contact" in x["reason"] for x in s["skipped"])

    def aborted(d):
        d["/biotac"] = d["/biotac"].isel(time=slice(0, 950))          # stops inside the second straw
        d["/"] = d["/"].assign_attrs(status="aborted")
        return d
    store = _rewrite(src, tmp_path / "aborted", aborted)
    s = analyze_run(store, FAST, console=lambda *a: None)
    assert any(x["what"] == "run" and "aborted" in x["reason"] for x in s["skipped"])
    assert s["headline"]["crossings"] == 2
    assert (store.parent / "analysis" / "summary.json").exists() and (store.parent / "analysis" / "analysis.zarr.zip").is_file()

    # a level this close to the peak leaves 'during' segments of < 2 frames (a sweep's 'during'
    # lasts as long as its electrodes stay above estimates.width_level of their rise)
    store = _copy(src, tmp_path, "short")
    s = analyze_run(store, {**FAST, "estimates": {"width_level": 0.9999}}, console=lambda *a: None)
    short = [x for x in s["skipped"] if "shorter than two frames" in x["reason"]]
    assert short and all(x["what"] == "segment during" for x in short)


def test_cli_errors_are_one_line(tmp_path):
    env = dict(os.environ, TACTILE_CACHE_DIR=os.environ.get("TACTILE_CACHE_DIR", str(tmp_path / "cache")))
    (tmp_path / "junk").mkdir()
    r = subprocess.run([str(BIN / "tactile-analyze"), f"run={tmp_path / 'junk'}"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and r.stderr.strip().count("\n") == 0, r.stderr
    r = subprocess.run([str(BIN / "tactile-analyze"), f"run={tmp_path}", "analysis.segmentation.prominence=7"],
                       cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 2


def _results(summary: dict) -> dict:
    """A summary without what differs between two analyses of the same run (ids, times, config)."""
    return {k: v for k, v in summary.items() if k not in ("analysis_id", "provenance", "timing", "run")}


def test_workers_give_identical_results(runs, tmp_path):
    """The (window, view) jobs on 1 or 3 threads and the figures here or in 3 forked processes:
    the same summary, to the last bit, and the same PNG files, to the byte."""
    results = {}
    for workers in (1, 3):
        store = _copy(runs["straws_sweep"], tmp_path, f"w{workers}")
        summary = analyze_run(store, {**FAST, "figures": True, "workers": workers}, console=lambda *a: None)
        pngs = {p.name: p.read_bytes() for p in (store.parent / "analysis" / "figures").iterdir()}
        results[workers] = json.dumps(_results(summary), sort_keys=True), pngs
    assert len(results[1][1]) == 7 and sorted(json.loads(results[1][0])["figures"]) == sorted(results[1][1])
    assert results[1] == results[3]


def test_a_figure_that_fails_in_a_worker_fails_the_analysis_and_leaves_nothing(runs, tmp_path, monkeypatch):
    """A fault of one figure, drawn in a forked worker, reaches the caller as that figure's own
    error; nothing of the analysis is left in the run directory and no worker outlives it."""
    from tactile_flow.analysis import figures

    def broken(a):
        raise ValueError("taxels figure: broken on purpose")
    monkeypatch.setattr(figures, "taxels", broken)
    store = _copy(runs["straws_sweep"], tmp_path, "broken")
    with pytest.raises(ValueError, match="broken on purpose"):
        analyze_run(store, {**FAST, "figures": True, "workers": 2}, console=lambda *a: None)
    assert sorted(p.name for p in store.parent.iterdir()) == [".tactile.lock", "run.zarr"]   # the lock file stays
    assert not multiprocessing.active_children()


def test_static_flow_only_where_an_estimate_reads_it(runs, tmp_path):
    """A sweep's estimates are the same with the static flow in every view (flow.static=all) or
    only in the slip's evidence views (auto); the other views' static aggregates are then absent."""
    auto = analyze_run(_copy(runs["straws_sweep"], tmp_path, "auto"), FAST, console=lambda *a: None)
    full = analyze_run(_copy(runs["straws_sweep"], tmp_path, "all"), {**FAST, "flow": {"static": "all"}},
                       console=lambda *a: None)
    assert json.dumps(auto["estimates"], sort_keys=True) == json.dumps(full["estimates"], sort_keys=True)
    assert [s["slip"] for s in auto["segments"]] == [s["slip"] for s in full["segments"]]
    during = next(s for s in full["segments"] if s["label"] == "during")
    assert {"bottom/static", "left/static", "right/static"} <= set(during["flow"])
    during = next(s for s in auto["segments"] if s["label"] == "during")
    assert "bottom/static" in during["flow"] and "left/static" not in during["flow"]
    assert "left/dynamic" in during["flow"]


def test_sweeps_and_pour_write_only_documented_fields(runs, tmp_path):
    """Every field of their summary.json is in docs/analysis.md's table (tests/test_summary_fields.py)."""
    from test_summary_fields import undocumented
    for proto, store in runs.items():
        summary = analyze_run(_copy(store, tmp_path, proto), {"progress": False}, console=lambda *a: None)
        assert undocumented(summary) == [], proto


def _figures(analysis_dir: Path) -> dict:
    return {p.name: p.read_bytes() for p in (analysis_dir / "figures").iterdir()}


def test_a_reanalysis_links_the_figures_whose_inputs_it_shares_and_they_are_as_drawn_afresh(runs, tmp_path):
    """A second analysis of a run (another name, another config) links the figures whose inputs
    are unchanged from the earlier one and draws the others; every file is byte for byte what
    an analysis with that config draws on a run never analysed; force=true draws them all."""
    store = _copy(runs["straws_sweep"], tmp_path, "again")
    base = {"progress": False, "figures": True, "workers": 1, "max_segment_figures": 2}
    analyze_run(store, base, name="first", console=lambda *a: None)
    kept = store.parent / "analyses"
    changes = {"flow": {"flow": {"winsize": 11}},                           # the flow figures change
               "segments": {"estimates": {"width_level": 0.45}}}           # the segments change too
    for tag, change in changes.items():
        lines = []                                     # the second one draws what changed in 2 forked workers
        analyze_run(store, {**base, **change, "workers": 1 if tag == "flow" else 2}, name=tag, console=lines.append)
        fresh = _copy(runs["straws_sweep"], tmp_path, f"fresh_{tag}")
        analyze_run(fresh, {**base, **change}, name=tag, console=lambda *a: None)
        assert _figures(kept / tag) == _figures(fresh.parent / "analyses" / tag), tag
        reused = analyses.read_meta(kept / tag)["figures_reused"]
        assert reused and len(reused) < len(_figures(kept / tag)), (tag, reused)
        assert f"{len(reused)} of {len(_figures(kept / tag))} figures as drawn before" in lines[-1]
        for name in _figures(kept / tag):              # a reused file is the earlier file (a hard link)
            same = (kept / tag / "figures" / name).stat().st_ino == (kept / "first" / "figures" / name).stat().st_ino
            assert same == (name in reused), (tag, name)
    assert "electrodes.png" in analyses.read_meta(kept / "segments")["figures_reused"]    # no segments drawn on it
    assert "pressure.png" not in analyses.read_meta(kept / "segments")["figures_reused"]
    assert {n for n in _figures(kept / "flow") if n.startswith("flow_")}.isdisjoint(
        analyses.read_meta(kept / "flow")["figures_reused"])
    before = _figures(kept / "flow")
    analyze_run(store, {**base, **changes["flow"]}, name="flow", force=True, console=lambda *a: None)
    assert analyses.read_meta(kept / "flow")["figures_reused"] == [] and _figures(kept / "flow") == before


def test_figures_named_draws_only_those_the_same_files_and_the_rest_later(runs, tmp_path):
    """``figures=[pressure, flow]`` (what one reads of each short record of a dataset) draws
    pressure.png and the flow figures, byte for byte those an analysis with every figure draws;
    a later analysis with every figure links them and draws only the others; an unknown
    figure is refused, naming the ones there are."""
    from tactile_flow.analysis.config import AnalysisConfigError, load_config
    store = _copy(runs["straws_sweep"], tmp_path, "named")
    base = {"progress": False, "workers": 1, "max_segment_figures": 2}
    summary = analyze_run(store, {**base, "figures": ["flow", "pressure"]}, name="named", console=lambda *a: None)
    kept = store.parent / "analyses"
    named = _figures(kept / "named")
    assert sorted(summary["figures"]) == sorted(named)
    assert "pressure.png" in named and len(named) == 3 and all(n == "pressure.png" or n.startswith("flow_")
                                                                for n in named)
    lines = []
    analyze_run(store, {**base, "figures": True}, name="all", console=lines.append)
    every = _figures(kept / "all")
    assert len(every) == 4 + len(named) - 1 and {n: every[n] for n in named} == named
    assert sorted(analyses.read_meta(kept / "all")["figures_reused"]) == sorted(named)
    with pytest.raises(AnalysisConfigError, match="unknown figure 'pressur'.*electrodes, pressure"):
        load_config({"figures": ["pressur"]})
    assert load_config({"figures": []}).figures is False
