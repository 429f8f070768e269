"""Every field ``summary.json`` holds is documented, with its unit, in docs/analysis.md.

The table "``summary.json``, field by field" names each field by its path (``a.b`` a key, ``a[]``
every item of a list, ``<placeholder>`` any one name, ``<slip>`` a slip estimate wherever it
sits; in a cell of several names, one that begins with ``.`` continues the first name's parent);
a field an analysis writes that no row names fails here. The analyses checked: a slip in
place from the simulated lab, an imported record with one finger dead and one saturated (null
slip estimates with their reasons), real touches; the sweeps and the pour are checked in
``tests/test_analysis_runs.py`` on its runs (:func:`undocumented`).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

DOC = Path(__file__).resolve().parents[1] / "docs" / "analysis.md"
SLIP = r"(?:segments\[\]\.slip|estimates\.slip\.[^.\[\]]+)"


def documented() -> list[re.Pattern]:
    """The table's paths as patterns (module docstring)."""
    text = DOC.read_text()
    start = text.index("### `summary.json`, field by field")
    rows = [line for line in text[start:].splitlines()[1:] if line.startswith("| `")]
    out = []
    for row in rows:
        cell = row.split(" | ")[0].lstrip("| ")
        names = re.findall(r"`([^`]+)`", cell)
        parent = names[0].rsplit(".", 1)[0] if "." in names[0] else ""
        for name in names:
            path = parent + name if name.startswith(".") else name
            pattern = re.escape(path).replace(re.escape("<slip>"), SLIP)
            pattern = re.sub(r"<[a-z_/<>]+>", r"[^.\\[\\]]+", pattern.replace("\\<", "<").replace("\\>", ">"))
            out.append(re.compile(pattern + r"\Z"))
    return out


def leaves(obj, prefix=""):
    """The paths of ``obj``'s leaf values (module docstring's notation)."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from leaves(v, f"{prefix}.{k}" if prefix else k)
    elif isinstance(obj, list) and obj and all(isinstance(v, dict) for v in obj):
        for v in obj:
            yield from leaves(v, prefix + "[]")
    elif obj != []:                            # an empty list says nothing of its items
        yield prefix


def undocumented(summary: dict) -> list[str]:
    """The fields of ``summary`` (leaves; an opaque config is one field) no table row names."""
    patterns = documented()
    found = set()
    for path in leaves(summary):
        if path.startswith(("provenance.config.", "provenance.config_overrides.")):
            continue
        if not any(p.match(path) for p in patterns):
            found.add(re.sub(r"\.(ff|mf|rf|lf|th)(?=\.|$)", ".<finger>", path))
    return sorted(found)


def test_the_table_parses_and_catches_a_new_field():
    patterns = documented()
    assert len(patterns) > 100
    assert undocumented({"headline": {"segments": 3, "slip": {"ff": {"slip_onset_s": 1.0}}},
                         "segments": [{"slip": {"evidence": {"motion": {"displacement_mm": 1.0}}}}]}) == []
    assert undocumented({"headline": {"brand_new_number": 1}}) == ["headline.brand_new_number"]
    assert undocumented({"estimates": {"slip": {"mf": {"unheard_of": 1}}}}) == ["estimates.slip.<finger>.unheard_of"]


@pytest.mark.slow
def test_a_slip_in_place_and_an_import_with_bad_fingers_write_only_documented_fields(tmp_path, model):
    import real_touch as rt
    from tactile_flow.analysis.run import analyze_run
    from tactile_flow.importers import ImportSettings, import_source
    from tactile_flow.protocols.slip_grid import Condition, run_slip_in_place
    summaries = []
    for c in (Condition("translate", 60.0, tare=False), Condition("rotate", rotation_deg=-30.0, press_force=5.0)):
        r = run_slip_in_place(tmp_path / c.name, c)
        summaries.append(analyze_run(r.store, {"progress": False}, console=lambda *a: None))
    noise = rt.rest_noise()
    counts = np.clip(3000.0 + noise[:600], 1, 4094)
    counts[100:500, 0, 20:24] -= 400
    counts[:, 1] = 4095
    counts[150:, 2] = 0
    names = [f"{f}_e{k}" for f in ("ff", "mf", "th") for k in range(1, 25)]
    src = tmp_path / "bad.csv"
    src.write_text(",".join(names) + "\n" + "\n".join(",".join(str(int(v)) for v in row.ravel())
                                                      for row in counts) + "\n")
    (res,) = import_source(src, tmp_path / "imported", ImportSettings(rate_hz=100.0, fingers=("ff", "mf", "th")))
    summaries.append(analyze_run(res.store, {"figures": False, "progress": False}, console=lambda *a: None))
    assert summaries[-1]["estimates"]["slip"]["mf"]["reason"]
    for s in summaries:
        assert undocumented(s) == [], s["run"]
