"""A tactile sensor described as data: :class:`SensorModel`, read once from its file.

A sensor is one YAML file (``conf/sensor/<name>.yaml``; ``docs/sensors.md`` explains every
field): its taxel positions (mm, sensor frame) and normals, the surface the taxel values are
carried over (a half-ellipsoid fitted to the taxels or given, or a flat rectangle) and the
views rendered from it, how raw electrode counts become the activation the method uses
(the impedance, for BioTacs), its pressure, vibration and temperature channels with their
rates, its physical limits, and what the simulator needs to imitate it at rest.

:func:`load_sensor` checks the file once — every key and type, required fields, the
geometry (finite, distinct positions; normals of non-zero length; every taxel on its surface)
— and returns a frozen :class:`SensorModel` that the rest of the code takes; a bad file is a
:class:`SensorModelError`, one line naming the file, the field and what was expected. The
model's :attr:`~SensorModel.sha256` is a checksum of its canonical content (not of the file's
text: comments and layout do not count), recorded with every run store so that an analysis
cannot pair a store with another geometry.

Sensor frame (the SynTouch convention, both BioTacs): x along the finger (+ towards the tip),
y lateral, z normal to the pad, contact side z < 0.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.resources
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tactile_flow.validation import ConfigError, brief, build, spec

__all__ = ["DEFAULT_SENSOR", "ChannelSpec", "ElectrodeSpec", "LimitsSpec", "SensorModel", "SensorModelError",
           "SurfaceShape", "SurfaceSpec", "builtin_sensor", "builtin_sensors", "load_sensor", "load_sensor_file",
           "sensor_file", "sensor_for_taxels"]

DEFAULT_SENSOR = "biotac_sp"
SURFACE_KINDS = ("ellipsoid", "plane")
SURFACE_FITS = ("positions", "positions_and_normals", "given")
ACTIVATIONS = ("impedance",)
DUPLICATE_MM = 1e-6
"""Two taxels closer than this (mm) are the same position written twice."""


class SensorModelError(ConfigError):
    """A sensor file that cannot be used: ``<file>: <key>: what was wrong; what was expected``."""

    def __init__(self, key: str, message: str, file: str | None = None):
        super().__init__(key, message)
        self.file = file
        if file:
            self.args = (f"{file}: {key}: {message}",)

    def __str__(self) -> str:
        return self.args[0]


# ----------------------------------------------------------------------------- the file's schema
@dataclass
class TaxelsSpec:
    """``taxels``: where the taxels are (mm, sensor frame) and which way each faces."""
    positions_mm: list[list[float]] = spec(factory=list)       # required: N rows of [x, y, z]
    names: list[str] | None = None                               # default E1..EN
    normals: Any = "surface"                                     # "surface" or N rows of [nx, ny, nz]


@dataclass
class SurfaceSpec:
    """``surface``: what the taxel values are carried over.

    ``kind`` ``ellipsoid``: the contact half (z ≤ centre z) of an axis-aligned ellipsoid,
    ``fit`` to the taxel ``positions`` (least squares, :func:`tactile.ellipsoid.fit_ellipsoid`),
    to the positions ``and_normals`` (the given normals weighted by ``normal_weight``), or
    ``given`` as ``centre_mm`` and ``axes_mm`` (semi-axes along x, y, z). ``kind`` ``plane``:
    a flat rectangle facing −z, centred at ``centre_mm`` with ``size_mm`` (x, y) — fitted: the
    taxels' mean height and their extent plus ``margin_mm`` on every side. Every taxel must lie
    within ``tolerance_mm`` of the surface. ``pad_radius_mm``: the taxels within this distance
    (in x–y, mm) of the pad's lowest point are the *pad* (:attr:`SensorModel.pad`), whose summed
    activation is the signal feature widths are measured on; ``null``: every taxel."""
    kind: str = spec("ellipsoid", choices=SURFACE_KINDS)
    fit: str = spec("positions", choices=SURFACE_FITS)
    centre_mm: list[float] | None = spec(None, length=3)
    axes_mm: list[float] | None = spec(None, length=3)
    size_mm: list[float] | None = spec(None, length=2)
    margin_mm: float = spec(2.0, ge=0)
    normal_weight: float = spec(3.0, gt=0)
    tolerance_mm: float = spec(1.0, gt=0)
    pad_radius_mm: float | None = spec(None, gt=0)


@dataclass
class ViewSpec:
    """A camera of ``custom_views`` (:class:`tactile.frames.View`)."""
    look: list[float] = spec(factory=lambda: [0.0, 0.0, 1.0], length=3)
    up: list[float] = spec(factory=lambda: [0.0, -1.0, 0.0], length=3)
    half: str = spec("facing", choices=("facing", "all"))


@dataclass
class ElectrodeSpec:
    """``electrodes``: how the taxels' raw counts become the activation.

    ``activation: impedance`` (BioTacs): the electrode is a voltage divider against a
    ``reference_kohm`` resistor read by an ADC of full scale ``counts_max``, so its impedance
    is ``Z = (counts_max / E − 1) · reference_kohm`` kΩ; the activation is ``Z − Z_rest``."""
    counts_max: int = spec(4095, gt=0)
    activation: str = spec("impedance", choices=ACTIVATIONS)
    reference_kohm: float = spec(10.0, gt=0)
    rate_hz: float = spec(100.0, gt=0)
    bandwidth_hz: float | None = spec(None, gt=0)


@dataclass
class ChannelSpec:
    """A scalar channel per sensor (``pressure``, ``vibration``, ``temperature``, ...):
    its stored ``name``, ADC ``counts_max``, sample ``rate_hz`` and samples per frame, and
    its physical meaning (``units_per_count`` in ``units``; ``range`` in those units)."""
    name: str = ""
    rate_hz: float = spec(100.0, gt=0)
    samples_per_frame: int = spec(1, ge=1)
    counts_max: int = spec(4095, gt=0)
    units: str = ""
    units_per_count: float | None = None
    range: list[float] | None = spec(None, length=2)
    estimate: bool = False


@dataclass
class LimitsSpec:
    """``limits``: the sensor's physical limits. ``electrode_counts``: [low, high] counts
    outside which an electrode reading is not a measurement (0: shorted or disconnected;
    full scale: saturated); ``max_force_n``: the normal force it is rated for."""
    electrode_counts: list[float] = spec(factory=lambda: [1.0, 4094.0], length=2)
    max_force_n: float | None = spec(None, gt=0)
    estimate: bool = False


@dataclass
class SimulationSpec:
    """``simulation``: what the simulated sensor needs beyond the contact model of
    ``hardware.sensor``. ``rest_calibration``: resting statistics measured on a real sensor
    (a JSON in ``hardware/sim``, one template per sensor); with another taxel count than the
    file's, each taxel takes the statistics of the template's electrode at the same rank
    (an estimate, said in ``notes``)."""
    rest_calibration: str = "biotac_rest_calibration.json"
    notes: str = ""


@dataclass
class SensorSpec:
    """A sensor file (``conf/sensor/<name>.yaml``)."""
    name: str = ""
    description: str = ""
    source: str = ""
    taxels: TaxelsSpec = field(default_factory=TaxelsSpec)
    surface: SurfaceSpec = field(default_factory=SurfaceSpec)
    views: list[str] = spec(factory=lambda: ["bottom", "left", "right"])
    custom_views: dict[str, ViewSpec] = field(default_factory=dict)
    frame_size: list[int] | None = spec(None, length=2)        # (H, W) px of the frames; null: the analysis's
    electrodes: ElectrodeSpec = field(default_factory=ElectrodeSpec)
    pressure: ChannelSpec | None = None
    vibration: ChannelSpec | None = None
    temperature: ChannelSpec | None = None
    temperature_change: ChannelSpec | None = None
    limits: LimitsSpec = field(default_factory=LimitsSpec)
    simulation: SimulationSpec = field(default_factory=SimulationSpec)
    live_slip: dict[str, float] = field(default_factory=dict)    # the live slip detector's thresholds for it


#: keys a sensor file must set (the others have the defaults above)
REQUIRED = ("name", "taxels", "taxels.positions_mm", "surface", "surface.kind", "views", "electrodes")
#: the stored channels, by the role the file gives them (``pressure: {name: pdc}``)
CHANNEL_ROLES = ("pressure", "vibration", "temperature", "temperature_change")


# ----------------------------------------------------------------------------- the model
@dataclass(frozen=True, eq=False)
class SurfaceShape:
    """The surface a model's taxels are carried over, fitted or given (mm, sensor frame).

    ``kind`` ``ellipsoid``: ``centre`` (3,) and ``extent`` (3,) semi-axes along x, y, z; its
    contact half z ≤ centre z. ``plane``: ``centre`` (3,) of the rectangle and ``extent`` (2,)
    its size along x and y, facing −z. ``rms_mm``: the taxels' root-mean-square distance to it.
    """
    kind: str
    centre: np.ndarray
    extent: np.ndarray
    rms_mm: float

    def __post_init__(self):
        for name in ("centre", "extent"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def pole(self) -> np.ndarray:
        """(3,) the lowest point of the pad (contact side), mm: where a press is centred."""
        if self.kind == "plane":
            return np.array(self.centre)
        return self.centre + np.array([0.0, 0.0, -self.extent[2]])

    @property
    def reach_mm(self) -> float:
        """Radius of a sphere about :attr:`centre` that holds the whole surface, mm."""
        return float(np.max(self.extent) if self.kind == "ellipsoid" else np.hypot(*self.extent) / 2)


@dataclass(frozen=True, eq=False)
class SensorModel:
    """A validated sensor (build it with :func:`load_sensor`; never re-read its file).

    Attributes:
        name: the model's name (``biotac_sp``, ``biotac``, ...).
        taxel_names: (N,) names, ``E1``..``EN`` unless the file names them.
        taxels: (N, 3) read-only taxel positions, mm, sensor frame.
        normals: (N, 3) read-only unit normals (the file's, or the surface's at each taxel:
            ``normals_source``).
        surface: the surface's description (:class:`SurfaceSpec`); the fitted or given
            shape is :attr:`shape` (:class:`SurfaceShape`).
        views: names of the views rendered; ``custom_views``: name → ``tactile.frames.View`` kwargs;
            ``frame_size``: (H, W) px of the rendered frames, or ``None`` (the analysis's ``tactile.size``).
        electrodes, pressure, vibration, temperature, temperature_change, limits, simulation:
            the file's sections (``None``: the sensor has no such channel).
        live_slip: thresholds of the live slip detector (:class:`tactile.slip.SlipConfig`) this
            sensor's signals need, where the run's ``live.slip`` keeps the default.
        spec: the canonical content (plain JSON types), what :attr:`sha256` is the checksum of.
        file: the file it came from (``None`` for a model given as data).
    """

    name: str
    description: str
    source: str
    taxel_names: tuple[str, ...]
    taxels: np.ndarray
    normals: np.ndarray
    normals_source: str
    surface: SurfaceSpec
    shape: SurfaceShape
    views: tuple[str, ...]
    custom_views: dict
    frame_size: tuple[int, int] | None
    electrodes: ElectrodeSpec
    pressure: ChannelSpec | None
    vibration: ChannelSpec | None
    temperature: ChannelSpec | None
    temperature_change: ChannelSpec | None
    limits: LimitsSpec
    simulation: SimulationSpec
    live_slip: dict
    spec: dict = field(repr=False)
    sha256: str = ""
    file: str | None = None

    @property
    def n_taxels(self) -> int:
        return len(self.taxels)

    @property
    def pad(self) -> np.ndarray | None:
        """(N,) bool, the pad's taxels (within ``surface.pad_radius_mm`` of the lowest point in
        x–y), or ``None`` when every taxel is the pad."""
        r = self.surface.pad_radius_mm
        if r is None:
            return None
        return np.linalg.norm(self.taxels[:, :2] - self.shape.pole[:2], axis=1) <= r

    @property
    def pad_centre(self) -> np.ndarray:
        """(3,) mm, the centroid of the pad's taxels (:attr:`pad`; of every taxel when every taxel
        is the pad): where the taxels put an object resting on the pad, the reference of the slip
        estimate's unloaded centre of pressure (the classic BioTac's taxels reach 12 mm further
        towards the tip than the back, so their centroid is 3.2 mm off the pad)."""
        pad = self.pad
        return self.taxels.mean(axis=0) if pad is None else self.taxels[pad].mean(axis=0)

    @property
    def counts_max(self) -> int:
        """Full scale of the electrode ADC (counts)."""
        return int(self.electrodes.counts_max)

    @property
    def valid_counts(self) -> tuple[float, float]:
        """[low, high] electrode counts of a usable reading (``limits.electrode_counts``)."""
        lo, hi = self.limits.electrode_counts
        return float(lo), float(hi)

    def impedance(self, counts) -> np.ndarray:
        """Raw electrode counts (any shape) → the level the activation is the change of: the
        electrode impedance, kΩ (``electrodes.activation: impedance``); ValueError for counts
        outside 1..counts_max (:func:`tactile.signals.counts_to_impedance`)."""
        from .signals import counts_to_impedance
        e = self.electrodes
        return counts_to_impedance(counts, e.counts_max, e.reference_kohm)

    def channel(self, role: str) -> ChannelSpec | None:
        """The channel of ``role`` (pressure, vibration, temperature, temperature_change) or None."""
        return getattr(self, role)

    def channel_names(self) -> dict[str, str]:
        """Stored name → role of every scalar channel the sensor has (e.g. ``{"pdc": "pressure"}``)."""
        return {c.name: role for role in CHANNEL_ROLES if (c := getattr(self, role)) is not None}

    @property
    def pac_per_frame(self) -> int:
        """Vibration samples delivered with each frame (0 without a vibration channel)."""
        return int(self.vibration.samples_per_frame) if self.vibration is not None else 0

    def summary(self) -> dict:
        """What a run store records beside the full model: name, taxel count, checksum, file."""
        return {"name": self.name, "n_taxels": self.n_taxels, "sha256": self.sha256, "file": self.file}

    def describe(self) -> str:
        """``biotac_sp (24 taxels, sha256 1a2b3c4d)``: the model in one phrase, for messages."""
        return f"{self.name} ({self.n_taxels} taxels, sha256 {self.sha256[:8]})"


def _err(file, key, message) -> SensorModelError:
    return SensorModelError(key, message, file)


def _require(data: dict, file, key: str) -> None:
    """Refuse a sensor file that does not set every key of :data:`REQUIRED`."""
    for dotted in REQUIRED:
        node, parts = data, dotted.split(".")
        for i, part in enumerate(parts):
            if not isinstance(node, dict) or part not in node or node[part] is None:
                where = ".".join([key, *parts[:i + 1]])
                what = {"taxels.positions_mm": "a list of [x, y, z] taxel positions, mm",
                        "surface.kind": f"one of {', '.join(SURFACE_KINDS)}",
                        "views": "a list of the views rendered (bottom, left, right, or custom_views)"}
                raise _err(file, where, f"missing; expected {what.get('.'.join(parts[:i + 1]), 'this key')}")
            node = node[part]


def _rows(file, key: str, value, width: int, what: str) -> np.ndarray:
    """``value`` as an (n, width) float array of finite numbers, or the error naming the row."""
    if not isinstance(value, (list, tuple)) or not value:
        raise _err(file, key, f"got {brief(value)}; expected a non-empty list of {what}")
    out = np.empty((len(value), width))
    for i, row in enumerate(value):
        if not isinstance(row, (list, tuple)) or len(row) != width:
            raise _err(file, f"{key}[{i}]", f"got {brief(row)}; expected {what}")
        for j, x in enumerate(row):
            if isinstance(x, bool) or not isinstance(x, (int, float)):
                raise _err(file, f"{key}[{i}]", f"got {brief(row)}; expected {what}")
            if not np.isfinite(x):
                raise _err(file, f"{key}[{i}]", f"got {brief(row)}; expected finite numbers ({what})")
            out[i, j] = float(x)
    return out


def canonical(spec_: SensorSpec) -> dict:
    """The spec as plain JSON types, keys sorted: what the checksum covers."""
    return json.loads(json.dumps(dataclasses.asdict(spec_), sort_keys=True))


def checksum(content: dict) -> str:
    """SHA-256 of the canonical JSON text of ``content``."""
    text = json.dumps(content, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def load_sensor(data, *, file: str | None = None, key: str = "sensor", cache_dir=None) -> SensorModel:
    """A validated :class:`SensorModel` from ``data`` (a dict or OmegaConf node, as the file
    holds it). ``file``: where it came from, named in errors and recorded with runs.

    Raises :class:`SensorModelError` (one line: file, key, what was expected) for a missing
    or unknown key, a value of the wrong type, non-finite or duplicated positions, names or
    normals that do not match the positions in number, normals of zero length or pointing
    into the surface, a taxel off its surface (farther than ``surface.tolerance_mm``, or
    above an ellipsoid's rim), an unknown view.
    """
    from tactile_flow.validation import to_plain
    raw = to_plain(data)
    if not isinstance(raw, dict):
        raise _err(file, key, f"got {brief(raw)}; expected a mapping (a sensor file)")
    _require(raw, file, key)
    try:
        s = build(SensorSpec, raw, key)
    except SensorModelError:
        raise
    except ConfigError as exc:
        raise _err(file, exc.key, exc.message) from None
    if not s.name or not s.name.replace("_", "").replace("-", "").isalnum():
        raise _err(file, f"{key}.name", f"got {brief(s.name)}; expected a name of letters, digits, _ and -")
    taxels = _rows(file, f"{key}.taxels.positions_mm", s.taxels.positions_mm, 3, "[x, y, z] in mm")
    n = len(taxels)
    names = tuple(s.taxels.names) if s.taxels.names is not None else tuple(f"E{i}" for i in range(1, n + 1))
    if len(names) != n:
        raise _err(file, f"{key}.taxels.names", f"got {len(names)} names; expected one per position ({n})")
    if len(set(names)) != n:
        dup = next(x for x in names if names.count(x) > 1)
        raise _err(file, f"{key}.taxels.names", f"{dup!r} is given twice; expected distinct names")
    d = np.linalg.norm(taxels[:, None] - taxels[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    if (d < DUPLICATE_MM).any():
        i, j = sorted(int(k) for k in np.argwhere(d < DUPLICATE_MM)[0])
        raise _err(file, f"{key}.taxels.positions_mm[{j}]", f"{taxels[j].tolist()} is the position of "
                                                            f"[{i}] too; expected distinct taxel positions")
    given_normals = None
    if isinstance(s.taxels.normals, str):
        if s.taxels.normals != "surface":
            raise _err(file, f"{key}.taxels.normals", f"got {brief(s.taxels.normals)}; expected 'surface' or a list "
                                                      f"of [nx, ny, nz] rows, one per taxel")
    else:
        given_normals = _rows(file, f"{key}.taxels.normals", s.taxels.normals, 3, "[nx, ny, nz]")
        if len(given_normals) != n:
            raise _err(file, f"{key}.taxels.normals", f"got {len(given_normals)} normals; expected one per "
                                                      f"taxel position ({n})")
        length = np.linalg.norm(given_normals, axis=1)
        if (length < 1e-9).any():
            k = int(np.argmax(length < 1e-9))
            raise _err(file, f"{key}.taxels.normals[{k}]", f"{given_normals[k].tolist()} has zero length; "
                                                           f"expected a direction (normalised on reading)")
        given_normals = given_normals / length[:, None]
    views, custom = _views(s, file, key)
    if s.frame_size is not None and min(s.frame_size) < 8:
        raise _err(file, f"{key}.frame_size", f"got {s.frame_size}; expected [H, W] of at least 8 x 8 px")
    lo, hi = s.limits.electrode_counts
    if not 0 <= lo < hi <= s.electrodes.counts_max:
        raise _err(file, f"{key}.limits.electrode_counts", f"got {[lo, hi]}; expected [low, high] with "
                                                           f"0 <= low < high <= electrodes.counts_max "
                                                           f"({s.electrodes.counts_max})")
    from .slip import SlipConfig
    known = {f.name for f in dataclasses.fields(SlipConfig)}
    for k, v in s.live_slip.items():
        if k not in known:
            from tactile_flow.validation import unknown_key
            exc = unknown_key(f"{key}.live_slip", k, known, "threshold")
            raise _err(file, exc.key, exc.message)
        if not v > 0:
            raise _err(file, f"{key}.live_slip.{k}", f"got {v!r}; expected a number > 0")
    names_used = [c.name for role in CHANNEL_ROLES if (c := getattr(s, role)) is not None]
    for role in CHANNEL_ROLES:
        c = getattr(s, role)
        if c is not None and (not c.name.isidentifier() or names_used.count(c.name) > 1):
            raise _err(file, f"{key}.{role}.name", f"got {brief(c.name)}; expected a distinct channel name "
                                                   f"(letters, digits, _)")
    shape = _surface_shape(s.surface, taxels, given_normals, file, key, cache_dir)
    surface_normals = _surface_normals(shape, taxels)
    if given_normals is not None:
        cos = np.sum(given_normals * surface_normals, axis=1)
        if (cos <= 0).any():
            k = int(np.argmin(cos))
            raise _err(file, f"{key}.taxels.normals[{k}]", f"{given_normals[k].round(3).tolist()} points into the "
                                                           f"surface (its outward normal there is "
                                                           f"{surface_normals[k].round(3).tolist()}); expected outward "
                                                           f"normals")
    if s.surface.pad_radius_mm is not None and not (
            np.linalg.norm(taxels[:, :2] - shape.pole[:2], axis=1) <= s.surface.pad_radius_mm).any():
        raise _err(file, f"{key}.surface.pad_radius_mm", f"{s.surface.pad_radius_mm:g} mm holds no taxel; expected "
                                                         f"a radius about the lowest point {shape.pole.round(2).tolist()} "
                                                         f"that holds the pad's taxels")
    content = canonical(s)
    taxels.setflags(write=False)
    normals = given_normals if given_normals is not None else surface_normals
    normals.setflags(write=False)
    return SensorModel(name=s.name, description=s.description, source=s.source, taxel_names=names,
                       taxels=taxels, normals=normals, normals_source="file" if given_normals is not None else "surface",
                       surface=s.surface, shape=shape, views=views, custom_views=custom,
                       frame_size=tuple(s.frame_size) if s.frame_size is not None else None, electrodes=s.electrodes,
                       pressure=s.pressure, vibration=s.vibration, temperature=s.temperature,
                       temperature_change=s.temperature_change, limits=s.limits, simulation=s.simulation,
                       live_slip=dict(s.live_slip),
                       spec=content, sha256=checksum(content), file=str(file) if file else None)


def _views(s: SensorSpec, file, key) -> tuple[tuple[str, ...], dict]:
    from .frames import DEFAULT_VIEWS
    custom = {}
    for name, v in s.custom_views.items():
        for part in ("look", "up"):
            vec = np.asarray(getattr(v, part), float)
            if not np.isfinite(vec).all() or np.linalg.norm(vec) == 0:
                raise _err(file, f"{key}.custom_views.{name}.{part}", f"got {getattr(v, part)}; expected a "
                                                                      f"non-zero direction")
        if np.linalg.norm(np.cross(v.look, v.up)) < 1e-9:
            raise _err(file, f"{key}.custom_views.{name}.up", "is parallel to look; expected a direction across it")
        custom[name] = {"look": tuple(v.look), "up": tuple(v.up), "half": v.half}
    known = {**DEFAULT_VIEWS, **custom}
    if not s.views:
        raise _err(file, f"{key}.views", "empty; expected at least one view")
    for i, v in enumerate(s.views):
        if v not in known:
            raise _err(file, f"{key}.views[{i}]", f"unknown view {v!r}; expected one of {', '.join(sorted(known))} "
                                                  f"(or define it in custom_views)")
    if len(set(s.views)) != len(s.views):
        raise _err(file, f"{key}.views", f"{s.views}: a view is named twice")
    return tuple(s.views), custom


def _surface_shape(surf: SurfaceSpec, taxels, normals, file, key, cache_dir) -> SurfaceShape:
    """The fitted or given surface, checked against the taxels."""
    k = f"{key}.surface"
    if surf.fit == "given":
        for name in ("centre_mm", "axes_mm" if surf.kind == "ellipsoid" else "size_mm"):
            if getattr(surf, name) is None:
                raise _err(file, f"{k}.{name}", f"missing; expected it with fit: given ({surf.kind})")
    elif surf.fit == "positions_and_normals" and normals is None:
        raise _err(file, f"{k}.fit", "positions_and_normals needs taxels.normals; expected them given, or "
                                     "fit: positions")
    if surf.kind == "plane":
        if surf.fit == "positions_and_normals":
            raise _err(file, f"{k}.fit", "expected positions or given for a plane")
        if surf.fit == "given":
            centre, size = np.asarray(surf.centre_mm, float), np.asarray(surf.size_mm, float)
            if (size <= 0).any():
                raise _err(file, f"{k}.size_mm", f"got {surf.size_mm}; expected two lengths > 0 mm")
        else:
            lo, hi = taxels[:, :2].min(0) - surf.margin_mm, taxels[:, :2].max(0) + surf.margin_mm
            size = hi - lo
            if (size <= 0).any():
                raise _err(file, f"{key}.taxels.positions_mm", "the taxels lie on a line; expected them to span a "
                                                               "plane (or margin_mm > 0)")
            centre = np.r_[(lo + hi) / 2, taxels[:, 2].mean()]
        off = np.abs(taxels[:, 2] - centre[2])
        outside = (np.abs(taxels[:, :2] - centre[:2]) > size / 2 + 1e-9).any(axis=1)
        _check_on(file, key, surf, taxels, off, outside, "outside the plane's rectangle")
        return SurfaceShape("plane", centre, size, float(np.sqrt(np.mean(off ** 2))))
    from .disk_cache import cached_fit_ellipsoid
    from .ellipsoid import _project_np
    if surf.fit == "given":
        centre, axes = np.asarray(surf.centre_mm, float), np.asarray(surf.axes_mm, float)
        if (axes <= 0).any():
            raise _err(file, f"{k}.axes_mm", f"got {surf.axes_mm}; expected three semi-axes > 0 mm")
    else:
        if len(taxels) < 6:
            raise _err(file, f"{key}.taxels.positions_mm", f"{len(taxels)} taxels; expected at least 6 to fit an "
                                                           f"ellipsoid (or surface.fit: given)")
        try:
            fit = cached_fit_ellipsoid(taxels, normals=None if surf.fit == "positions" else normals,
                                       normal_weight=surf.normal_weight, cache_dir=cache_dir)
        except ValueError as exc:
            raise _err(file, f"{k}.fit", f"the fit failed ({exc}); expected taxels spread over a curved surface")
        centre, axes = np.asarray(fit.centre), np.asarray(fit.axes)
    foot = _project_np(axes, taxels - centre)
    off = np.linalg.norm(foot - (taxels - centre), axis=1)
    above = foot[:, 2] > 1e-9 * axes[2]
    _check_on(file, key, surf, taxels, off, above, "above the ellipsoid's rim (the surface is its half z < centre)")
    return SurfaceShape("ellipsoid", centre, axes, float(np.sqrt(np.mean(off ** 2))))


def _check_on(file, key, surf, taxels, off, outside, why):
    far = np.flatnonzero(off > surf.tolerance_mm)
    if far.size:
        i = int(far[np.argmax(off[far])])
        raise _err(file, f"{key}.taxels.positions_mm[{i}]",
                   f"{taxels[i].tolist()} is {off[i]:.2f} mm off the {surf.kind} surface ({surf.fit}); expected "
                   f"every taxel within surface.tolerance_mm = {surf.tolerance_mm:g} mm of it")
    if np.any(outside):
        i = int(np.argmax(outside))
        raise _err(file, f"{key}.taxels.positions_mm[{i}]", f"{taxels[i].tolist()} is {why}; expected every taxel "
                                                            f"on the surface")


def _surface_normals(shape, taxels) -> np.ndarray:
    """(N, 3) unit outward normals of the surface at the taxels' closest points."""
    if shape.kind == "plane":
        return np.tile([0.0, 0.0, -1.0], (len(taxels), 1))
    from .ellipsoid import _project_np, ellipsoid_normals
    return ellipsoid_normals(shape.extent, _project_np(shape.extent, taxels - shape.centre))


# ----------------------------------------------------------------------------- files
def sensor_file(name: str) -> Path:
    """The file of the built-in sensor ``name`` (``conf/sensor/<name>.yaml`` in the package)."""
    return Path(str(importlib.resources.files("tactile_flow.conf").joinpath("sensor", f"{name}.yaml")))


def builtin_sensors() -> dict[str, Path]:
    """Name → file of every sensor shipped with the package."""
    folder = Path(str(importlib.resources.files("tactile_flow.conf").joinpath("sensor")))
    return {p.stem: p for p in sorted(folder.glob("*.yaml"))}


_CACHE: dict = {}


def load_sensor_file(path, *, key: str = "sensor", cache_dir=None) -> SensorModel:
    """:func:`load_sensor` of a YAML file (a Hydra group file: ``# @package`` lines are comments)."""
    import yaml
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise _err(str(path), key, f"cannot be read ({type(exc).__name__}); expected a sensor file") from None
    try:
        data = yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))   # libyaml's when built in
    except yaml.YAMLError as exc:
        raise _err(str(path), key, f"not valid YAML ({str(exc).splitlines()[0]})") from None
    return load_sensor(data, file=str(path), key=key, cache_dir=cache_dir)


def builtin_sensor(name: str = DEFAULT_SENSOR) -> SensorModel:
    """The built-in sensor ``name``, read and checked once per process."""
    if name not in _CACHE:
        files = builtin_sensors()
        if name not in files:
            raise SensorModelError("sensor", f"no built-in sensor {name!r}; expected one of {', '.join(files)}")
        _CACHE[name] = load_sensor_file(files[name])
    return _CACHE[name]


def sensor_for_taxels(n: int, models=None) -> SensorModel:
    """The one built-in model (or of ``models``) with ``n`` taxels; a :class:`SensorModelError`
    listing the models and their counts when none or several have it."""
    models = list(models) if models is not None else [builtin_sensor(name) for name in builtin_sensors()]
    match = [m for m in models if m.n_taxels == n]
    if len(match) == 1:
        return match[0]
    listing = ", ".join(f"{m.name} ({m.n_taxels})" for m in models)
    if not match:
        raise SensorModelError("sensor", f"{n} electrodes match no sensor model; the models and their electrode "
                                         f"counts: {listing}")
    raise SensorModelError("sensor", f"{n} electrodes match several sensor models ({listing}); choose one "
                                     f"with sensor=NAME")
