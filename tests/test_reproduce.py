"""``tactile-runs reproduce``: a run done again from its directory alone, bit-identical on the
simulated lab (issue 32, part 1).

Real ``tactile-run`` and ``tactile-runs`` processes. The tests of an edited tree run the
project from a copy of it made a git repository of its own (``clone``): a ``sitecustomize``
on ``PYTHONPATH`` points the editable install's import mapping at the copy, so the copy's
code runs, is recorded and is compared, and the edit never touches the real checkout.
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tactile_flow.runstore import checksum, reproduce as repro

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[1]
QUIET = ("progress=false", "analysis.progress=false", "analysis.figures=false")

USER_PROTOCOL = """# @package _global_
# a lab's own protocol, kept outside the package (hydra.searchpath)
defaults:
  - /surface: my_board
protocol:
  name: my_sweep
  labels: [approach, before, during, after, lift]
  finger: ff
  sweep_speed: 12.0
  sweep_depth: 1.5
  steps:
    - move_to: {at: "before:first", height: 10.0}
    - approach: {depth: "${protocol.sweep_depth}", until: {force: 15.0}}
    - sweep: {to: "after:last", speed: "${protocol.sweep_speed}"}
    - lift: {height: 20.0}
"""


def run_cmd(module: str, *args, cwd, env=None, timeout=600):
    return subprocess.run([sys.executable, "-c", f"from {module} import main; main()", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def tactile_run(*args, cwd, env=None):
    return run_cmd("tactile_flow.protocols.entry", *args, cwd=cwd, env=env)


def tactile_runs(*args, cwd, env=None):
    proc = subprocess.run([sys.executable, "-c", "import sys; from tactile_flow.runstore.runs_cli import main; "
                           "sys.exit(main())", *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    return proc


def user_folder(root: Path) -> Path:
    folder = root / "lab_conf"
    (folder / "protocol").mkdir(parents=True)
    (folder / "surface").mkdir()
    (folder / "protocol" / "my_sweep.yaml").write_text(USER_PROTOCOL)
    board = (ROOT / "conf" / "surface" / "straws.yaml").read_text().replace("name: straws", "name: my_board")
    (folder / "surface" / "my_board.yaml").write_text(board.replace("count: 3", "count: 2"))
    return folder


def test_a_run_from_a_search_path_folder_reproduces_bit_identical_after_the_folder_is_gone(tmp_path):
    folder = user_folder(tmp_path)
    rec = tactile_run(*QUIET, f"hydra.searchpath=[file://{folder}]", "protocol=my_sweep", "hardware.seed=7",
                      "hydra.run.dir=run", cwd=tmp_path)
    assert rec.returncode == 0, rec.stderr
    info = json.loads((tmp_path / "run" / "run.json").read_text())
    copies = {f["copy"] for f in info["inputs"]["files"]}
    assert {"config/1/protocol/my_sweep.yaml", "config/1/surface/my_board.yaml", "config/main/config.yaml"} <= copies
    assert info["inputs"]["cwd"] == str(tmp_path) and "hydra.searchpath=" in " ".join(info["inputs"]["hydra_overrides"])
    shutil.rmtree(folder)                                                # the lab's folder is gone

    again = tactile_runs("reproduce", "run", "--out", "again", cwd=tmp_path)
    assert again.returncode == 0, (again.stdout, again.stderr)
    assert "reproduced: identical" in again.stdout
    a = json.loads((tmp_path / "again" / "run.json").read_text())
    assert a["store_checksum"]["sha256"] == info["store_checksum"]["sha256"]
    assert checksum.store_checksum(tmp_path / "again" / "run.zarr") == info["store_checksum"]      # from the files
    assert a["reproduces"]["run_id"] == info["run_id"] and a["config"] == info["config"]
    assert len(info["store_checksum"]["arrays"]) > 50

    other = tactile_run(*QUIET, "hydra.run.dir=other", "protocol.sweep_speed=20", cwd=tmp_path)   # not the same run
    assert other.returncode == 0
    c = repro.compare(tmp_path / "run", tmp_path / "other")
    assert not c.identical and "biotac/electrodes" in c.arrays and "protocol.name" in c.config
    assert c.line().startswith("reproduced: differs:")


def test_bad_input_is_one_line_and_nothing_is_written(tmp_path):
    rec = tactile_run(*QUIET, "hydra.run.dir=run", "analyze=false", cwd=tmp_path)
    assert rec.returncode == 0, rec.stderr
    (tmp_path / "junk").mkdir()
    info = json.loads((tmp_path / "run" / "run.json").read_text())

    def refused(target, *extra, expect):
        before = sorted(p.name for p in tmp_path.iterdir())
        proc = tactile_runs("reproduce", str(target), *extra, cwd=tmp_path)
        assert proc.returncode == 2, (proc.stdout, proc.stderr)
        assert len(proc.stderr.strip().splitlines()) == 1 and expect in proc.stderr, proc.stderr
        assert sorted(p.name for p in tmp_path.iterdir()) == before
    refused(tmp_path / "junk", expect="not a run directory")
    refused(tmp_path / "nowhere", expect="no such directory")
    newer = tmp_path / "newer"
    shutil.copytree(tmp_path / "run", newer)
    (newer / "run.json").write_text(json.dumps({**info, "schema_version": "2.0"}))
    refused(newer, expect="newer than this reader")
    altered = tmp_path / "altered"
    shutil.copytree(tmp_path / "run", altered)
    with open(altered / "config" / "main" / "protocol" / "straws_sweep.yaml", "a") as f:
        f.write("# edited after the run\n")
    refused(altered, expect="altered since the run was recorded")
    missing = tmp_path / "missing"
    shutil.copytree(tmp_path / "run", missing)
    (missing / "config" / "main" / "hardware" / "sim.yaml").unlink()
    refused(missing, expect="missing")
    tampered = tmp_path / "tampered"
    shutil.copytree(tmp_path / "run", tampered)
    import zarr
    z = zarr.open_array(str(tampered / "run.zarr"), path="biotac/pdc", mode="r+")
    z[0, 0] = z[0, 0] + 1
    refused(tampered, expect="biotac/pdc differs from run.json's checksum")


# ----------------------------------------------------------------------------- another code version
@pytest.fixture(scope="module")
def clone(tmp_path_factory):
    """A copy of the project's tree as a git repository of its own, and the environment that
    runs its code (the editable install's mapping pointed at it)."""
    root = tmp_path_factory.mktemp("clone")
    tree = root / "tactile-flow"
    listed = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-co", "--exclude-standard", "-z"],
                            capture_output=True, check=True).stdout.decode().split("\0")
    for rel in filter(None, listed):
        src = ROOT / rel
        if src.is_file():
            (tree / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, tree / rel)
    git = ["git", "-C", str(tree), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run(["git", "init", "-q", str(tree)], check=True)
    subprocess.run([*git, "add", "-A"], check=True)
    subprocess.run([*git, "commit", "-qm", "the project"], check=True)
    shim = root / "shim"
    shim.mkdir()
    (shim / "sitecustomize.py").write_text(
        "import sys\n"
        "for name, mod in list(sys.modules.items()):\n"
        "    if name.startswith('__editable__') and hasattr(mod, 'MAPPING'):\n"
        f"        mod.MAPPING.update({{k: v.replace({str(ROOT)!r}, {str(tree)!r}) for k, v in mod.MAPPING.items()}})\n")
    env = {**os.environ, "PYTHONPATH": str(shim)}
    where = subprocess.run([sys.executable, "-c", "import tactile_flow.runstore.provenance as p; print(p.PROJECT_ROOT)"],
                           env=env, capture_output=True, text=True, check=True).stdout.strip()
    assert where == str(tree), where
    return tree, env, git


def test_a_run_on_an_edited_tree_is_refused_once_the_edit_is_gone_and_reproduces_with_its_diff(clone, tmp_path):
    """The acceptance test of issue 32: the run keeps its diff (code.diff); with the edit
    reverted, reproduce refuses in one line naming the commit and how to restore it; with
    --allow-code-change it runs on this code (both versions recorded); with the stored diff
    applied (as docs/reproducibility.md says) it reproduces bit-identical."""
    tree, env, git = clone
    edited = tree / "hardware" / "sim" / "world.py"
    original = edited.read_text()
    edited.write_text(original + "\n# a local experiment, never committed\n")
    new_file = tree / "protocols" / "lab_notes.py"
    new_file.write_text('"""An untracked module of the lab."""\n')
    rec = tactile_run(*QUIET, "hydra.run.dir=run", cwd=tmp_path, env=env)
    assert rec.returncode == 0, rec.stderr
    run = tmp_path / "run"
    info = json.loads((run / "run.json").read_text())
    assert info["code"]["dirty"] and info["code"]["diff_file"] == "code.diff"
    diff = (run / "code.diff").read_text()
    assert "a local experiment, never committed" in diff and "protocols/lab_notes.py" in diff

    edited.write_text(original)                                          # the edit is gone
    new_file.unlink()
    refused = tactile_runs("reproduce", "run", "--out", "again", cwd=tmp_path, env=env)
    assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) == 1, refused.stderr
    assert "uncommitted changes" in refused.stderr and "git apply RUN/code.diff" in refused.stderr
    assert "--allow-code-change" in refused.stderr and not (tmp_path / "again").exists()

    allowed = tactile_runs("reproduce", "run", "--out", "allowed", "--allow-code-change", cwd=tmp_path, env=env)
    assert allowed.returncode == 0 and "reproduced: identical" in allowed.stdout, (allowed.stdout, allowed.stderr)
    both = json.loads((tmp_path / "allowed" / "run.json").read_text())
    assert both["reproduces"]["code"]["diff_sha256"] == info["code"]["diff_sha256"]
    assert both["code"]["diff_sha256"] is None and both["reproduces"]["code_changed"]

    subprocess.run([*git, "apply", str(run / "code.diff")], check=True)   # the documented way back
    assert "a local experiment" in edited.read_text() and new_file.exists()
    again = tactile_runs("reproduce", "run", "--out", "again", cwd=tmp_path, env=env)
    assert again.returncode == 0 and "reproduced: identical" in again.stdout, (again.stdout, again.stderr)
    assert json.loads((tmp_path / "again" / "run.json").read_text())["code"]["diff_sha256"] == info["code"]["diff_sha256"]
    edited.write_text(original)
    new_file.unlink()


def test_a_run_recorded_before_0_2_reproduces_from_its_overrides(tmp_path):
    """A run recorded by 0.1 (no copies, no code.diff, the old module names in its record):
    composed from the package's files and its recorded overrides; the config comparison says
    whether that gave the same run."""
    rec = tactile_run(*QUIET, "hydra.run.dir=run", "protocol.sweep_speed=15", cwd=tmp_path)
    assert rec.returncode == 0, rec.stderr
    run = tmp_path / "run"
    info = json.loads((run / "run.json").read_text())
    for key in ("inputs", "code", "cwd"):
        info.pop(key)
    info["command"] = ["/usr/bin/tactile-run", *info["overrides"]]
    info["git"] = {**info["git"], "dirty": False}
    (run / "run.json").write_text(json.dumps(info))
    shutil.rmtree(run / "config")
    (run / "code.diff").unlink(missing_ok=True)
    hydra_yaml = run / ".hydra" / "hydra.yaml"
    hydra_yaml.write_text(hydra_yaml.read_text().replace("tactile_flow.protocols.cli", "protocols.cli"))
    again = tactile_runs("reproduce", "run", "--out", "again", "--allow-code-change", cwd=tmp_path)
    assert again.returncode == 0 and "reproduced: identical" in again.stdout, (again.stdout, again.stderr)


def test_a_run_recorded_with_a_retired_analysis_key_reproduces_and_says_it_is_ignored(tmp_path):
    """``analysis.pour.rotation_rad`` (retired in 0.3) in a run's recorded config: the run is
    done again (with --allow-code-change, as any run of older code), the key named as ignored."""
    rec = tactile_run(*QUIET, "hydra.run.dir=run", cwd=tmp_path)
    assert rec.returncode == 0, rec.stderr
    recorded = tmp_path / "run" / "config" / "main" / "analysis" / "default.yaml"
    text = recorded.read_text()
    assert "rotation_noise_k: 6.0" in text
    recorded.write_text(text.replace("rotation_noise_k: 6.0", "rotation_rad: 0.015"))
    info = json.loads((tmp_path / "run" / "run.json").read_text())      # as 0.2 recorded it
    for f in info["inputs"]["files"]:
        if f["copy"].endswith("analysis/default.yaml"):
            f["sha256"] = repro._sha256(recorded)
    pour = info["config"]["analysis"]["pour"]
    pour["rotation_rad"] = 0.015
    del pour["rotation_noise_k"]
    (tmp_path / "run" / "run.json").write_text(json.dumps(info))
    again = tactile_runs("reproduce", "run", "--out", "again", "--allow-code-change", cwd=tmp_path)
    assert again.returncode == 0 and "reproduced: identical" in again.stdout, (again.stdout, again.stderr)
    assert "analysis.pour.rotation_rad is retired and ignored" in again.stdout + again.stderr
