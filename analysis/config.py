"""The ``analysis`` config node → validated :class:`AnalysisConfig` (and a ``TactileConfig``).

The node is the ``analysis`` group of the composed Hydra config (``conf/analysis/default.yaml``),
an OmegaConf ``DictConfig`` or a plain dict. Missing keys take the defaults below; unknown keys
and wrong types are :class:`AnalysisConfigError` naming the key (``analysis.segmentation.xxx``).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import Any

from tactile_flow.tactile import flow as tflow
from tactile_flow.tactile.geodesic import GEODESIC_METHODS
from tactile_flow.tactile.surface import KERNEL_FORMS
from tactile_flow.tactile.pipeline import TactileConfig
from tactile_flow.validation import ConfigError, build, spec, unknown_key


class AnalysisConfigError(ConfigError):
    """A bad analysis parameter: ``AnalysisConfigError("analysis.x: message")`` or
    ``AnalysisConfigError("analysis.x", "message")``; ``key`` names the key."""

    def __init__(self, key: str, message: str | None = None):
        if message is None:
            key, _, message = key.partition(": ")
        super().__init__(key, message)


@dataclass(frozen=True)
class Segmentation:
    smooth_s: float = spec(0.05, gt=0)
    contact_threshold_sigma: float = spec(6.0, gt=0)
    contact_min_pdc: float = 3.0
    contact_min_proxy: float = 1.5
    prominence_pdc: float = 20.0
    prominence_proxy: float = 2.0
    min_contact_s: float = spec(0.1, gt=0)
    merge_gap_s: float = 0.05
    prominence: float = spec(0.25, gt=0, lt=1)
    distance_s: float = spec(0.5, gt=0)
    plateau_level: float = spec(0.55, gt=0, lt=1)
    margin_s: float = 0.2
    settle_frames: int = spec(10, ge=1)
    load_fraction: float = spec(0.8, gt=0, le=1)


@dataclass(frozen=True)
class Estimates:
    width_signal: str = spec("taxels", choices=("taxels", "proxy", "pdc"))
    width_level: float = spec(0.5, gt=0, lt=1)
    width_taxel_fraction: float = spec(0.3, gt=0, le=1)
    width_load_fraction: float = spec(0.15, ge=0, lt=1)
    texture_angle: str = spec("passing", choices=("passing", "frame"))
    texture_taxel_fraction: float = spec(0.1, gt=0, le=1)
    texture_max_uncertainty_deg: float = spec(15.0, gt=0)
    min_speed_mm_s: float = 0.5


@dataclass(frozen=True)
class Pour:
    rotation_noise_k: float = spec(6.0, gt=0)
    trough_prominence: float = 0.15
    # retired in 0.3 (the rotation phase is read relative to the turn's own noise): accepted so
    # that a run recorded before re-runs (`tactile-runs reproduce`), and ignored, with a note
    rotation_rad: float | None = None


@dataclass(frozen=True)
class Contact:
    method: str = spec("auto", choices=("auto", "pressure", "pattern"))
    threshold_sigma: float = spec(6.0, gt=0)
    despike_frames: int = spec(5, ge=1)
    stored_uncertainty_counts: float = spec(10.0, ge=0)


@dataclass(frozen=True)
class Slip:
    min_displacement_mm: float = spec(1.5, ge=0)
    min_rotation_deg: float = spec(0.9, ge=0)
    min_still_rotation_deg: float = spec(0.45, ge=0)
    moving_confidence: float = spec(0.1, ge=0, le=1)
    arc_ratio: float = spec(0.04, ge=0)
    reference_s: float = spec(0.1, gt=0)
    reference_horizon_s: float = spec(1.0, gt=0)
    loaded_fraction: float = spec(0.5, ge=0, lt=1)
    min_decision_s: float = spec(0.3, ge=0)
    views: tuple = ("bottom",)


@dataclass(frozen=True)
class Memory:
    chunk_frames: int = spec(10000, ge=1000)
    noise_sample_frames: int = spec(50000, ge=1000)


REFERENCES = ("auto", "unloaded", "contact_onset", "time")


@dataclass(frozen=True)
class AnalysisConfig:
    """Every analysis parameter (units in ``conf/analysis/default.yaml``)."""

    enabled: bool = True
    tactile: TactileConfig = field(default_factory=TactileConfig)
    views: tuple[str, ...] = ("bottom", "left", "right")      # () in a config: the sensor model's (for_sensor)
    baseline_fallback_window_s: float = 0.5
    baseline_fallback_contact_min: float = 20.0
    pressure_signal: str = "auto"
    segmentation: Segmentation = field(default_factory=Segmentation)
    estimates: Estimates = field(default_factory=Estimates)
    pour: Pour = field(default_factory=Pour)
    contact: Contact = field(default_factory=Contact)
    slip: Slip = field(default_factory=Slip)
    memory: Memory = field(default_factory=Memory)
    reference: str = "auto"
    reference_time_s: float | None = None
    static_flow: str = "auto"                # flow.static: auto (where an estimate reads it) | all
    static_every: int = 4                    # flow.static_every: frames between static-flow computations
    workers: int | None = None               # flow job threads, figure and first-run compile processes; None: the cores available
    intensity: str = "contact"
    save_fields: bool = False
    figures: bool | tuple[str, ...] = True   # true: every figure; false: none; or the kinds to draw (FIGURE_KINDS)
    max_segment_figures: int = 12
    progress: bool = True
    raw: dict = field(default_factory=dict, compare=False)   # the node as given (for provenance)


_TACTILE_KEYS = {"kalman_r": float, "kalman_q": float, "smooth": bool, "sigma": float, "kernel": str,
                 "geodesic": str, "mesh_spacing": float, "scale": float, "render": str, "size": list,
                 "intensity_range": list, "noise": float, "chunk": int}
_FLOW_ANALYSIS_KEYS = {"reference", "reference_time_s", "static", "static_every"}
_FLOW_KEYS = {"method": str, "pyr_scale": float, "levels": int, "winsize": int, "iterations": int,
              "poly_n": int, "poly_sigma": float, "flags": int, "dis_preset": str, "dis": dict, "tvl1": dict}


def _plain(node) -> dict:
    if node is None:
        return {}
    try:
        from omegaconf import DictConfig, OmegaConf
        if isinstance(node, DictConfig):
            return OmegaConf.to_container(node, resolve=True)
    except ImportError:  # pragma: no cover
        pass
    if not isinstance(node, dict):
        raise AnalysisConfigError(f"analysis: expected a mapping, got {type(node).__name__}")
    return json.loads(json.dumps(node))


FIGURE_KINDS = ("electrodes", "pressure", "taxels", "ellipsoid", "flow")
"""The figures ``analysis.figures`` can name: ``electrodes.png``, ``pressure.png``, ``taxels.png``,
``ellipsoid.png`` and ``flow`` (every ``flow_<label>.png``)."""


def _figures(value) -> bool | tuple[str, ...]:
    """``analysis.figures``: true (every figure), false (none), or a list of :data:`FIGURE_KINDS`
    (e.g. ``[pressure, flow]``: what one reads of each short record of a dataset), kept in the
    order of :data:`FIGURE_KINDS` (an empty list is false)."""
    if isinstance(value, bool):
        return value
    if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        unknown = [v for v in value if v not in FIGURE_KINDS]
        if not unknown:
            return tuple(k for k in FIGURE_KINDS if k in value) or False
        raise AnalysisConfigError(f"analysis.figures: unknown figure {unknown[0]!r}; expected true, false or a list "
                                  f"of {', '.join(FIGURE_KINDS)}")
    raise AnalysisConfigError(f"analysis.figures: expected true, false or a list of {', '.join(FIGURE_KINDS)}, "
                              f"got {value!r}")


def _typed(key: str, value, kind):
    if kind is bool:
        if not isinstance(value, bool):
            raise AnalysisConfigError(f"analysis.{key}: expected true or false, got {value!r}")
        return value
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise AnalysisConfigError(f"analysis.{key}: expected an integer, got {value!r}")
        return value
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise AnalysisConfigError(f"analysis.{key}: expected a number, got {value!r}")
        return float(value)
    if kind is str:
        if not isinstance(value, str):
            raise AnalysisConfigError(f"analysis.{key}: expected a string, got {value!r}")
        return value
    if kind in (list, dict) and not isinstance(value, kind):
        raise AnalysisConfigError(f"analysis.{key}: expected a {kind.__name__}, got {value!r}")
    return value


def _section(cls, prefix: str, values: dict):
    try:
        return build(cls, values, f"analysis.{prefix}")
    except ConfigError as exc:
        raise AnalysisConfigError(exc.key, exc.message) from None


def _refuse_unknown(key: str, values, known) -> None:
    unknown = sorted(set(values) - set(known))
    if unknown:
        exc = unknown_key(key, unknown[0], known)
        raise AnalysisConfigError(exc.key, exc.message)


def _positive(key: str, value: float) -> None:
    if not value > 0:
        raise AnalysisConfigError(f"analysis.{key}: expected a value > 0, got {value!r}")


def load_config(node=None, sensor=None) -> AnalysisConfig:
    """Validate the ``analysis`` node (DictConfig, dict or None for the defaults); an
    :class:`AnalysisConfig` (checked already) is returned as it is. With ``sensor`` (a
    :class:`tactile.sensor.SensorModel`), the config for that sensor (:func:`for_sensor`): what
    ``tactile-run`` checks before anything moves."""
    if isinstance(node, AnalysisConfig):
        return node if sensor is None else for_sensor(node, sensor)
    cfg = _load_config(node)
    return cfg if sensor is None else for_sensor(cfg, sensor)


def _load_config(node) -> AnalysisConfig:
    raw = _plain(node)
    d = dict(raw)
    known = {"enabled", "tactile", "views", "flow", "baseline", "pressure", "segmentation", "estimates",
             "pour", "contact", "slip", "memory", "save_fields", "figures", "max_segment_figures", "progress", "workers"}
    _refuse_unknown("analysis", d, known)
    tac = dict(d.get("tactile") or {})
    # intensity_range: "contact" (each contact window spans 0..255 up to its own peak), or [low, high] kΩ
    intensity = "contact" if tac.get("intensity_range", "contact") == "contact" else "fixed"
    if intensity == "contact":
        tac.pop("intensity_range", None)
    if "size" in tac and tac["size"] is None:                  # null: the sensor model's frame size (for_sensor)
        tac.pop("size")
    _refuse_unknown("analysis.tactile", tac, _TACTILE_KEYS)
    fl = dict(d.get("flow") or {})
    reference = _typed("flow.reference", fl.pop("reference", "auto"), str)
    if reference not in REFERENCES:
        raise AnalysisConfigError(f"analysis.flow.reference: expected one of {', '.join(REFERENCES)}, got {reference!r}")
    static_flow = _typed("flow.static", fl.pop("static", "auto"), str)
    if static_flow not in ("auto", "all"):
        raise AnalysisConfigError(f"analysis.flow.static: expected auto or all, got {static_flow!r}")
    static_every = _typed("flow.static_every", fl.pop("static_every", 4), int)
    if static_every < 1:
        raise AnalysisConfigError(f"analysis.flow.static_every: expected an integer ≥ 1 (frames), got {static_every}")
    ref_time = fl.pop("reference_time_s", None)
    if ref_time is not None:
        ref_time = _typed("flow.reference_time_s", ref_time, float)
    if reference == "time" and (ref_time is None or not ref_time >= 0):
        raise AnalysisConfigError("analysis.flow.reference_time_s: expected a time ≥ 0 s (since run start) "
                                  f"with flow.reference=time, got {ref_time!r}")
    _refuse_unknown("analysis.flow", fl, set(_FLOW_KEYS) | _FLOW_ANALYSIS_KEYS)
    views = d.get("views")
    if views is None:
        views = []                                             # null: the sensor model's views (for_sensor)
    elif not isinstance(views, list) or not views or not all(isinstance(v, str) for v in views):
        raise AnalysisConfigError(f"analysis.views: expected a non-empty list of view names (or null: the sensor "
                                  f"model's), got {views!r}")
    tk = {k: _typed(f"tactile.{k}", v, _TACTILE_KEYS[k]) for k, v in tac.items()}
    for k, choices in (("render", ("exact", "linear")), ("kernel", KERNEL_FORMS), ("geodesic", GEODESIC_METHODS)):
        if k in tk and tk[k] not in choices:
            raise AnalysisConfigError(f"analysis.tactile.{k}", f"got {tk[k]!r}; expected one of {', '.join(choices)}")
    for k in ("size", "intensity_range"):
        if k in tk:
            if len(tk[k]) != 2:
                raise AnalysisConfigError(f"analysis.tactile.{k}: expected two numbers, got {tk[k]!r}")
            tk[k] = tuple(int(x) for x in tk[k]) if k == "size" else tuple(float(x) for x in tk[k])
    for k in ("kalman_r", "kalman_q", "sigma", "mesh_spacing"):
        if k in tk:
            _positive(f"tactile.{k}", tk[k])
    if isinstance(fl.get("dis_preset"), int) and not isinstance(fl["dis_preset"], bool):
        names = {i: n for n, i in tflow.DIS_PRESETS.items()}      # OpenCV's numbers, as before the names
        fl["dis_preset"] = names.get(fl["dis_preset"], fl["dis_preset"])
    try:
        fk = {k: _typed(f"flow.{k}", v, _FLOW_KEYS[k]) for k, v in fl.items()}
        flow_cfg = tflow.FlowConfig(**fk)
        tactile = TactileConfig(**tk, views=tuple(views), flow=flow_cfg)
    except AnalysisConfigError:
        raise
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        raise AnalysisConfigError(msg if msg.startswith("analysis.") else f"analysis.{msg}") from None
    seg = _section(Segmentation, "segmentation", d.get("segmentation") or {})
    est = _section(Estimates, "estimates", d.get("estimates") or {})
    pour = _section(Pour, "pour", d.get("pour") or {})
    base = d.get("baseline") or {}
    _refuse_unknown("analysis.baseline", base, ("fallback_window_s", "fallback_contact_min"))
    window = _typed("baseline.fallback_window_s", base.get("fallback_window_s", 0.5), float)
    _positive("baseline.fallback_window_s", window)
    fb_min = _typed("baseline.fallback_contact_min", base.get("fallback_contact_min", 20.0), float)
    _positive("baseline.fallback_contact_min", fb_min)
    pres = d.get("pressure") or {}
    _refuse_unknown("analysis.pressure", pres, ("signal",))
    signal = _typed("pressure.signal", pres.get("signal", "auto"), str)
    if signal not in ("auto", "pdc", "proxy"):
        raise AnalysisConfigError(f"analysis.pressure.signal: expected auto, pdc or proxy, got {signal!r}")
    con = _section(Contact, "contact", d.get("contact") or {})
    sl = dict(d.get("slip") or {})
    if "views" in sl:
        if not isinstance(sl["views"], list) or not sl["views"] or not all(v in views or not views for v in sl["views"]):
            raise AnalysisConfigError(f"analysis.slip.views: expected a non-empty list of the analysed views "
                                      f"{views}, got {sl['views']!r}")
        sl["views"] = tuple(sl["views"])
    slip = _section(Slip, "slip", sl)
    memory = _section(Memory, "memory", d.get("memory") or {})
    top = {k: _typed(k, d[k], t) for k, t in (("enabled", bool), ("save_fields", bool),
                                              ("max_segment_figures", int), ("progress", bool)) if k in d}
    if "figures" in d:
        top["figures"] = _figures(d["figures"])
    if d.get("workers") is not None:
        top["workers"] = _typed("workers", d["workers"], int)
        if top["workers"] < 1:
            raise AnalysisConfigError(f"analysis.workers: expected an integer ≥ 1 (or null: the cores available), "
                                      f"got {top['workers']}")
    return AnalysisConfig(tactile=tactile, views=tuple(views), baseline_fallback_window_s=window,
                          baseline_fallback_contact_min=fb_min,
                          pressure_signal=signal, segmentation=seg, estimates=est, pour=pour, contact=con,
                          slip=slip, memory=memory, reference=reference, reference_time_s=ref_time, static_flow=static_flow,
                          static_every=static_every,
                          intensity=intensity,
                          raw=raw, **top)


def for_sensor(cfg: AnalysisConfig, sensor) -> AnalysisConfig:
    """``cfg`` for the sensor model ``sensor`` (:class:`tactile.sensor.SensorModel`): with no
    ``analysis.views`` given, the sensor's views, and with no ``analysis.tactile.size``, its
    ``frame_size`` (when it gives one); views it does not have (nor
    ``tactile.custom_views``) are an :class:`AnalysisConfigError` naming them, as are slip
    evidence views outside the analysed ones (a flat pad has only ``bottom``)."""
    tactile = cfg.tactile
    if sensor.frame_size is not None and (cfg.raw.get("tactile") or {}).get("size") is None:
        tactile = dataclasses.replace(tactile, size=tuple(sensor.frame_size))
    known = (*sensor.views, *cfg.tactile.custom_views)
    views = tuple(cfg.views) or tuple(sensor.views)
    for i, view in enumerate(views):
        if view not in known:                        # a misspelt view: refused before the run, with the nearest
            raise AnalysisConfigError(f"analysis.views[{i}]", unknown_key("analysis.views", view, known, what=(
                f"view of sensor {sensor.name}")).message)
    slip_views = tuple(v for v in cfg.slip.views if v in views)
    if not slip_views:
        raise AnalysisConfigError("analysis.slip.views", f"{list(cfg.slip.views)}: none of them is analysed for sensor "
                                                         f"{sensor.name} (views {', '.join(views)})")
    if "views" in (cfg.raw.get("slip") or {}) and slip_views != tuple(cfg.slip.views):
        raise AnalysisConfigError("analysis.slip.views", f"{list(cfg.slip.views)}: expected some of the analysed "
                                                         f"views {list(views)}")
    return dataclasses.replace(cfg, views=views, tactile=dataclasses.replace(tactile, views=views),
                               slip=dataclasses.replace(cfg.slip, views=slip_views))


def as_dict(cfg: AnalysisConfig) -> dict[str, Any]:
    """The effective configuration, JSON-ready (for provenance and the history)."""
    def conv(x):
        if dataclasses.is_dataclass(x):
            return {f.name: conv(getattr(x, f.name)) for f in dataclasses.fields(x) if f.name != "raw"}
        if isinstance(x, (tuple, list)):
            return [conv(v) for v in x]
        if isinstance(x, dict):
            return {str(k): conv(v) for k, v in x.items()}
        return x
    return conv(cfg)
