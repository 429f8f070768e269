"""The lab's per-sensor calibration stored with a run: the unloaded electrode counts.

A real lab keeps a calibration file (unloaded counts measured at the start of a session) so
that a record which starts in contact has a zero. ``hardware.biotac_calibration`` says where
it comes from:

- a path: a calibration JSON as ``tactile-import calibration=`` reads it
  (:func:`importers.baseline.load_calibration`; for the real lab too);
- ``simulated`` (``hardware=sim`` only): the simulated sensors' unloaded counts averaged over a
  short simulated rest before the run, off by the drift since
  (:meth:`hardware.sim.sensor.BiotacModel.session_calibration`) — realistically imperfect;
- ``null``: none stored (the hard case: the analysis must find the zero itself).

Stored as an import stores its baseline (``docs/import.md``): ``biotac/baseline`` (finger,
taxel) counts and the root attributes ``baseline`` {method, source, details, fingers} and
``calibration`` {finger: SensorCalibration}.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tactile_flow.hardware.errors import ConfigError
from tactile_flow.importers.baseline import Baseline, load_calibration
from tactile_flow.importers.recording import ImportInputError
from tactile_flow.importers.sources import sha256_file
from tactile_flow.tactile.signals import SensorCalibration

KEY = "hardware.biotac_calibration"


def session_baseline(hw, lab) -> Baseline | None:
    """The calibration ``hw.biotac_calibration`` names for ``lab``'s fingers, or ``None``;
    ``hw``: the typed hardware config (:class:`~protocols.settings.RunSettings` ``.hardware``).

    Raises :class:`~hardware.errors.ConfigError` naming the key for a missing or bad file, or
    ``simulated`` on a lab that does not simulate its sensors.
    """
    what = hw.biotac_calibration
    fingers = list(lab.biotac.fingers)
    if what is None:
        return None
    if what == "simulated":
        counts = getattr(lab.biotac, "session_calibration", None)
        if counts is None:
            raise ConfigError(KEY, "'simulated' is only for hardware=sim; give the lab's calibration JSON file "
                                   "(or null)")
        sensor = hw.sensor                        # the simulator's sensor model (hardware.config.SensorModelConfig)
        details = {"rest_s": sensor.calibration_rest_s, "drift_counts": sensor.calibration_drift_counts,
                   "common_drift_counts": sensor.calibration_common_drift_counts, "seed": hw.seed}
        cals = {f: SensorCalibration(np.clip(counts[f], 1, 4095), f"sim-{f}", "simulated session calibration")
                for f in fingers}
        return Baseline("simulated_calibration", cals,
                        "the simulated sensors' unloaded counts averaged over a rest before the run, plus the "
                        "drift since", details)
    path = Path(str(what)).expanduser()
    if not path.is_file():
        raise ConfigError(KEY, f"no such file {path}; expected a calibration JSON (docs/import.md), "
                               f"'simulated' (hardware=sim) or null")
    try:
        return load_calibration(path, fingers, sha256_file(path))
    except ImportInputError as exc:
        raise ConfigError(KEY, str(exc)) from None


def store_baseline(store, baseline: Baseline | None, fingers) -> dict:
    """Write ``baseline`` into ``store`` (see the module doc); returns the root attribute
    ``baseline`` (``{"method": "none", ...}`` when there is none, and nothing is written)."""
    if baseline is None:
        attrs = {"method": "none", "source": "none stored (hardware.biotac_calibration=null)"}
        store.set_attrs(baseline=attrs)
        return attrs
    attrs = baseline.to_attrs(fingers)
    store.write_variable("biotac", "baseline", baseline.counts(fingers), ("finger", "taxel"), "count",
                         f"unloaded electrode baseline from outside the record ({attrs['method']}: "
                         f"{attrs['source']})", method=attrs["method"])
    store.set_attrs(baseline=attrs, calibration=baseline.calibration_attrs(fingers))
    return attrs
