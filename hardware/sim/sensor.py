"""BioTac signal model: resting statistics calibrated on a real recording, plus load.

Resting behaviour per sensor comes from the sensor model's ``simulation.rest_calibration``
(``biotac_rest_calibration.json``, derived by :mod:`hardware.sim.calibrate` from a real
Shadow Hand bag of BioTac SPs, source cited inside): the three real sensors are templates;
simulated finger ``ff`` uses template 0, ``mf`` 1, ``th`` 2 (the fingers they were recorded
on), ``rf`` and ``lf`` reuse 0 and 1. Each simulated sensor perturbs its template's
baselines by ``baseline_jitter_counts`` so no two are identical. Electrode noise is AR(1)
with the real lag-1 autocorrelation and per-electrode std; drift is the real warm-up
slope, settling with ``drift_tau_s``. A sensor with another number of electrodes than the
templates (the classic BioTac's 19) gives each of its electrodes the statistics of the
template's electrode at the same rank (:func:`template_rows`): an estimate, which its
model file says. The ADC's full scale and reference resistor are the model's.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from .config import SensorModelConfig
from .contact import (contact_noise_kohm, counts_from_impedance, impedance_from_counts, impedance_kohm, pdc_rise,
                      quantise)

TEMPLATE_OF_FINGER = {"ff": 0, "mf": 1, "th": 2, "rf": 0, "lf": 1}
N_PAC = 22   # 2.2 kHz / 100 Hz (the PAC samples of a frame; the sensor model's vibration.samples_per_frame)
_PAC_T = np.arange(N_PAC) / 2200.0                  # (22,) s, the PAC samples of a frame
_RING_PHASE = 2 * np.pi * 250.0 * _PAC_T            # (22,) rad, a 250 Hz ring over them
_RING_DECAY = np.exp(-_PAC_T / 0.006)               # (22,) its 6 ms decay


@lru_cache(maxsize=4)
def load_sensor_calibration(name: str) -> dict:
    """The calibration JSON shipped in ``hardware/sim`` (or an absolute path)."""
    path = Path(name) if Path(name).is_absolute() else Path(__file__).with_name(name)
    if not path.exists():
        raise FileNotFoundError(f"hardware.sensor.calibration: no file {path}")
    return json.loads(path.read_text())


def template_rows(n_template: int, n: int) -> np.ndarray:
    """(n,) the template electrode whose statistics each of ``n`` electrodes takes: the one at
    the same rank, ``floor(k · n_template / n)`` (every electrode of the template for n = n_template)."""
    return (np.arange(n) * n_template) // n


@dataclass
class SensorInputs:
    """Physical inputs of all fingers for one frame (F = number of fingers, N taxels).

    ``load``: (F, N) normal load in each taxel's footprint, N; ``shear_load``: (F, N) shear
    load, N-equivalent (negative where it unloads); ``force``: (F,) total normal force N;
    ``force_rate``: (F,) dF/dt N/s; ``friction``: (F,) sliding friction force N.
    """

    load: np.ndarray
    force: np.ndarray
    force_rate: np.ndarray
    friction: np.ndarray
    shear_load: np.ndarray | None = None


class BiotacModel:
    """Per-finger parameters and noise state; :meth:`frame` turns loads into counts."""

    def __init__(self, fingers, cfg: SensorModelConfig, rng: np.random.Generator,
                 frame_dt: float = 0.01, sensor=None):
        """``sensor``: the :class:`tactile.sensor.SensorModel` imitated (default the BioTac SP);
        its ``simulation.rest_calibration`` replaces ``cfg.calibration`` (``hardware.sensor.calibration``)
        when it names another file than the default."""
        if sensor is None:
            from tactile_flow.tactile.sensor import builtin_sensor
            sensor = builtin_sensor()
        rest_file = sensor.simulation.rest_calibration or cfg.calibration
        cal = load_sensor_calibration(cfg.calibration if rest_file == SensorModelConfig.calibration else rest_file)
        self.cfg, self.rng, self.dt = cfg, rng, frame_dt
        self.sensor = sensor
        e = sensor.electrodes
        self._scale = (float(e.counts_max), float(e.reference_kohm))
        self.counts_max = int(e.counts_max)
        N = self.N = sensor.n_taxels
        tpl = [cal["sensors"][TEMPLATE_OF_FINGER[f] % len(cal["sensors"])] for f in fingers]
        rows = template_rows(len(tpl[0]["electrode_baseline"]), N)
        F = len(fingers)
        g = lambda k: np.array([t[k] for t in tpl], float)[:, rows]
        self.baseline = g("electrode_baseline") + rng.normal(0, cfg.baseline_jitter_counts, (F, N))
        self.baseline = np.clip(self.baseline, 200 * self.counts_max / 4095, 3900 * self.counts_max / 4095)
        self.z0 = impedance_from_counts(self.baseline, *self._scale)
        self.noise_std = cfg.noise_scale * g("electrode_noise_std") * rng.uniform(0.9, 1.1, (F, N))
        self.phi = float(np.median([t["electrode_noise_lag1"] for t in tpl]))
        self.drift = cfg.drift_scale * g("electrode_drift_per_s") * rng.uniform(0.8, 1.2, (F, N))
        s = lambda ch, k: np.array([t[ch][k] for t in tpl], float)
        self.pdc0, self.pdc_std, self.pdc_drift = s("pdc", "mean"), cfg.noise_scale * s("pdc", "noise_std"), \
            cfg.drift_scale * s("pdc", "drift_per_s")
        self.tdc0, self.tdc_std, self.tdc_drift = s("tdc", "mean"), cfg.noise_scale * s("tdc", "noise_std"), \
            cfg.drift_scale * s("tdc", "drift_per_s")
        self.tac0, self.tac_std = s("tac", "mean"), cfg.noise_scale * s("tac", "noise_std")
        self.pac0, self.pac_std = s("pac", "mean"), cfg.noise_scale * s("pac", "noise_std")
        self._ar = rng.normal(0, 1, (F, N)) * self.noise_std
        self._heat = np.zeros(F)
        self._pac_phase = rng.uniform(0, 2 * np.pi, F)
        self.F = F

    def _warmup(self, t: float) -> float:
        """Drift multiplier: seconds of equivalent linear drift after ``t`` s of warm-up."""
        tau = self.cfg.drift_tau_s
        return tau * (1.0 - np.exp(-t / tau))

    def session_calibration(self, rng: np.random.Generator) -> np.ndarray:
        """(F, N) the lab's calibration of these sensors: their unloaded counts averaged over a
        rest of ``calibration_rest_s`` taken at the session's start (AR(1) noise, as the frames),
        off by the drift between that calibration and the run: per electrode
        (``calibration_drift_counts``) and shared by a sensor's electrodes
        (``calibration_common_drift_counts``), both normal with these standard deviations."""
        c, F, N = self.cfg, self.F, self.N
        n = max(1, int(round(c.calibration_rest_s / self.dt)))
        ar = rng.standard_normal((F, N)) * self.noise_std
        total = np.zeros((F, N))
        for _ in range(n):
            ar = self.phi * ar + rng.standard_normal((F, N)) * self.noise_std * np.sqrt(1 - self.phi ** 2)
            total += ar
        drift = rng.normal(0, c.calibration_drift_counts, (F, N)) + rng.normal(0, c.calibration_common_drift_counts,
                                                                              (F, 1))
        return self.rest_counts(0.0) + total / n + drift

    def rest_counts(self, t: float) -> np.ndarray:
        """(F, N) noise-free unloaded electrode counts at time ``t`` (s): baseline + warm-up drift."""
        return self.baseline + self.drift * self._warmup(t)

    def frame(self, t: float, inp: SensorInputs):
        """Counts for one frame at time ``t`` (s): electrodes (F, N), pdc, tdc, tac (F,), pac (F, n_pac).

        Returns float arrays already quantised to integers in 0..counts_max.
        """
        c, rng, F, N, top = self.cfg, self.rng, self.F, self.N, self.counts_max
        w = self._warmup(t)
        rest = self.rest_counts(t)
        z_rest = impedance_from_counts(rest, *self._scale)
        shear = np.zeros_like(inp.load) if inp.shear_load is None else inp.shear_load
        z = impedance_kohm(z_rest, inp.load, shear, inp.force, c.saturation_load_n, c.shear_kohm_per_n,
                           c.far_rise_per_n)
        z = z + rng.standard_normal((F, N)) * contact_noise_kohm(z, z_rest, c.contact_noise_fraction * c.noise_scale)
        innov = rng.standard_normal((F, N)) * self.noise_std * np.sqrt(1 - self.phi ** 2)
        self._ar = self.phi * self._ar + innov
        electrodes = quantise(counts_from_impedance(z, *self._scale) + self._ar, hi=top)
        pdc = quantise(self.pdc0 + self.pdc_drift * w + pdc_rise(inp.force, c.pdc_counts_per_n, c.pdc_saturation_n)
                       + rng.standard_normal(F) * self.pdc_std, hi=top)
        # a first-order "heat absorbed" state: TAC dips while it catches up with the force
        k = self.dt / 1.0
        tac_term = c.tac_counts_per_n * (inp.force - self._heat)
        self._heat = self._heat + k * (inp.force - self._heat)
        tac = quantise(self.tac0 - tac_term + rng.standard_normal(F) * self.tac_std, hi=top)
        tdc = quantise(self.tdc0 + self.tdc_drift * w - 0.5 * c.tac_counts_per_n * self._heat
                       + rng.standard_normal(F) * self.tdc_std, hi=top)
        pac = self._pac(inp)
        return electrodes, pdc, tdc, tac, pac

    def _pac(self, inp: SensorInputs) -> np.ndarray:
        """22 PAC samples per finger: noise, a ringing burst on force changes (edges),
        broadband noise proportional to sliding friction."""
        c, rng = self.cfg, self.rng
        amp = c.pac_gain_per_n_s * np.abs(inp.force_rate)
        ring = amp[:, None] * np.sin(_RING_PHASE + self._pac_phase[:, None]) * _RING_DECAY
        self._pac_phase = (self._pac_phase + 2 * np.pi * 250.0 * N_PAC / 2200.0) % (2 * np.pi)
        slip = c.pac_slip_gain * inp.friction[:, None] * rng.standard_normal((self.F, N_PAC))
        noise = self.pac_std[:, None] * rng.standard_normal((self.F, N_PAC))
        return quantise(self.pac0[:, None] + ring + slip + noise)
