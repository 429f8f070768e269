"""The reference tables of docs/protocols.md, generated from the code so they cannot drift.

    python docs/protocol_tables.py           # rewrite the generated tables in docs/protocols.md
    python docs/protocol_tables.py --check   # exit 1 (naming the table) if docs/protocols.md differs from the code

Tables: every registered step kind (:data:`protocols.steps.STEP_KINDS`) with its dataclass
fields, types, defaults and units; the ``until`` criteria (:class:`protocols.steps.Criterion`);
the protocol-level parameters (:class:`protocols.schema.ProtocolConfig`, with the unit
comments of its source); the score targets (:mod:`analysis.score`). Each sits in
docs/protocols.md between ``<!-- BEGIN name -->`` and ``<!-- END name -->``.

A field's unit comes from :data:`UNITS` (by ``(kind, field)``, then by field name); a numeric
field without one is an error, so a new step kind cannot enter the table without its units.
A field whose default is ``None`` and which falls back to a protocol-level parameter
(``self.speed or ctx.params.sweep_speed``, ``ctx.params.hold_time if self.duration is None``)
shows that parameter, read from the step's source.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import inspect
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# tactile_flow from this tree (its folders are the package's subpackages), whatever is installed:
# the tables describe the code beside them
_spec = importlib.util.spec_from_file_location("tactile_flow", ROOT / "tactile_flow" / "__init__.py",
                                               submodule_search_locations=[str(ROOT / "tactile_flow"), str(ROOT)])
sys.modules["tactile_flow"] = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(sys.modules["tactile_flow"])

from tactile_flow.analysis import score  # noqa: E402
from tactile_flow.protocols.schema import ProtocolConfig  # noqa: E402
from tactile_flow.protocols.steps import REACTIONS, STEP_KINDS, Criterion  # noqa: E402

DOC = ROOT / "docs" / "protocols.md"

# Units of numeric fields, by (kind, field) first, then by field name.
UNITS = {
    "height": "mm", "margin": "mm", "depth": "mm", "distance": "mm", "speed": "mm/s", "duration": "s",
    "flexion": "rad", "joints": "rad", "rate": "ml/min", "volume": "ml", "force": "N", "pose": "m, rad",
    "times": "1", "angle": "deg", "direction_deg": "deg", "pdc_rise": "counts", "contact_lost": "counts",
    "dx": "mm", "dy": "mm", "dz": "mm",
    ("twist", "speed"): "deg/s",
}
# Fields whose default comes from the protocol in a way the source patterns below do not show.
PROTOCOL_DEFAULTS: dict[tuple[str, str], str] = {}

# ProtocolConfig fields that carry no comment in protocols/schema.py.
PROTOCOL_NOTES = {"name": "names the run directory and the store", "description": "one line for people",
                  "labels": "the segment labels the analysis produces; they choose its scheme",
                  "steps": "the steps, run in order (table below)"}
TYPES = {"float": "number", "int": "integer", "str": "text", "bool": "true/false", "list[str]": "list of text",
         "list[float]": "list of numbers", "dict[str, float]": "joint → number", "Criterion": "criterion",
         "list[Step]": "list of steps"}
TEXT_KINDS = {("move_to", "at"): "surface reference or `home`", ("sweep", "to"): "surface reference",
              ("grasp", "fingers"): "finger names", ("tighten", "fingers"): "finger names",
              ("pour", "on_slip"): "reactions", ("hold", "on_slip"): "reactions",
              ("grasp", "joints"): "Shadow joint → rad"}


def type_name(kind: str, f: dataclasses.Field) -> str:
    parts = [p.strip() for p in str(f.type).split("|")]
    optional = "None" in parts
    base = " or ".join(TEXT_KINDS.get((kind, f.name)) or TYPES.get(p, p) for p in parts if p != "None")
    return base + (" or null" if optional else "")


def unit(kind: str, f: dataclasses.Field) -> str:
    u = UNITS.get((kind, f.name), UNITS.get(f.name))
    numeric = any(t in str(f.type) for t in ("float", "int"))
    if u is None and numeric:
        raise SystemExit(f"docs/protocol_tables.py: no unit for the numeric field {kind}.{f.name}; "
                         f"add it to UNITS")
    return u or "—"


def protocol_default(cls, name: str) -> str | None:
    """The protocol parameter a ``None`` field falls back to, read from the class's source."""
    if (cls.kind, name) in PROTOCOL_DEFAULTS:
        return PROTOCOL_DEFAULTS[(cls.kind, name)]
    src = inspect.getsource(cls)
    for pattern in (rf"self\.{name} or ctx\.params\.(\w+)", rf"ctx\.params\.(\w+)\b[^\n]*?if self\.{name} is None"):
        m = re.search(pattern, src)
        if m:
            return m.group(1)
    return None


def default(cls, f: dataclasses.Field) -> str:
    value = f.default if f.default is not dataclasses.MISSING else f.default_factory()
    if value is None:
        param = protocol_default(cls, f.name)
        if param is None:
            return "not set"
        return f"`protocol.{param}` ({getattr(ProtocolConfig(), param)})"
    if isinstance(value, list):
        return "[" + ", ".join(map(str, value)) + "]" if value else "[]"
    return f"`{value}`" if isinstance(value, str) else str(value)


def doc_text(obj) -> str:
    """An object's docstring as one markdown line."""
    return " ".join((inspect.getdoc(obj) or "").split()).replace("``", "`")


def steps_table() -> str:
    rows = ["| step | field | type | default | unit |", "| --- | --- | --- | --- | --- |"]
    for kind, cls in STEP_KINDS.items():
        fields = [f for f in dataclasses.fields(cls) if f.name != "key"]
        name = f"`{kind}`" + (" (reaction)" if kind in REACTIONS else "")
        if not fields:
            rows.append(f"| {name} | — | | | |")
        for i, f in enumerate(fields):
            rows.append(f"| {name if i == 0 else ''} | `{f.name}` | {type_name(kind, f)} | {default(cls, f)} "
                        f"| {unit(kind, f)} |")
    rows.append("")
    rows += [f"- `{kind}`: {doc_text(cls)}" for kind, cls in STEP_KINDS.items()]
    return "\n".join(rows)


def criteria_table() -> str:
    rows = ["| criterion | type | unit |", "| --- | --- | --- |"]
    for f in dataclasses.fields(Criterion):
        rows.append(f"| `{f.name}` | {type_name('until', f)} | {unit('until', f)} |")
    return "\n".join(rows)


def protocol_table() -> str:
    """``ProtocolConfig``'s fields with their defaults and the comment beside each in the source."""
    comments = {}
    for line in inspect.getsource(ProtocolConfig).splitlines():
        m = re.match(r"\s+(\w+): [^=]+=.*?#\s*(.+)$", line)
        if m:
            comments[m.group(1)] = m.group(2).strip()
    base = ProtocolConfig()
    rows = ["| key | default | meaning (unit) |", "| --- | --- | --- |"]
    for f in dataclasses.fields(ProtocolConfig):
        value = getattr(base, f.name)
        shown = "required" if f.name == "name" else ("[]" if value == [] else f"`{value}`" if value != "" else '""')
        meaning = comments.get(f.name) or PROTOCOL_NOTES.get(f.name, "")
        rows.append(f"| `protocol.{f.name}` | {shown} | {meaning} |")
    return "\n".join(rows)


def targets_table() -> str:
    rows = ["| target | met when | checked on |", "| --- | --- | --- |"]
    where = {"direction_correct_fraction": "runs whose truth has feature crossings (sweeps)",
             "width_error_mm_median": "runs whose truth has feature crossings (sweeps)",
             "boundary_error_mm_median": "sweeps: segment boundaries in mm of travel (time error × sweep speed; "
                                         "a run with no boundary to measure counts as not met)",
             "boundary_error_ms_median": "pours: phase onsets (a run with no onset found counts as not met)",
             "slip_onset_error_ms": "pours (the analysis found pour phases)",
             "pour_phase_error_ms_max": "pours: every phase onset (the median alone hid a preset that moved one by seconds)"}
    for key, limit in score.TARGETS.items():
        u = re.search(r"_(mm|ms|deg)(?:_|$)", key)
        bound = f"≥ {limit:g} (all)" if key.endswith("fraction") else f"≤ {limit:g} {u.group(1) if u else ''}"
        rows.append(f"| `{key}` | {bound} | {where.get(key, '')} |")
    for key, limit in score.SLIP_TARGETS.items():
        rows.append(f"| `{key}` | ≥ {limit:g} (all) | runs whose truth has object motions under a still finger |")
    return "\n".join(rows)


TABLES = {"steps": steps_table, "criteria": criteria_table, "protocol": protocol_table, "targets": targets_table}


def render(text: str) -> str:
    """``text`` with every generated table replaced by the code's."""
    for name, make in TABLES.items():
        pattern = re.compile(rf"<!-- BEGIN {name} -->\n.*?<!-- END {name} -->", re.S)
        if not pattern.search(text):
            raise SystemExit(f"{DOC}: no <!-- BEGIN {name} --> ... <!-- END {name} --> block")
        text = pattern.sub(lambda m: f"<!-- BEGIN {name} -->\n{make()}\n<!-- END {name} -->", text)
    return text


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if docs/protocols.md differs from the code")
    args = parser.parse_args(argv)
    old = DOC.read_text()
    new = render(old)
    if args.check:
        stale = [n for n in TABLES if _block(old, n) != _block(new, n)]
        if stale:
            print(f"{DOC}: the generated table(s) {', '.join(stale)} differ from the code; "
                  f"run `python docs/protocol_tables.py`", file=sys.stderr)
            return 1
        return 0
    if new != old:
        DOC.write_text(new)
        print(f"{DOC}: tables updated")
    return 0


def _block(text: str, name: str) -> str:
    m = re.search(rf"<!-- BEGIN {name} -->\n(.*?)<!-- END {name} -->", text, re.S)
    return m.group(1) if m else ""


if __name__ == "__main__":
    sys.exit(main())
