"""Adding a stream is one place: a sample type that declares its columns (``describe()``).

A toy thermometer, declared here and nowhere else, is recorded through the real recorder
into a real run store, read back through the run store's reader, and recovered after a
crash, with no other file of the project knowing about it.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from tactile_flow.hardware.device import WallClock
from tactile_flow.hardware.streams import Column, Coord, Stream, device_time
from tactile_flow.protocols.recorder import Recorder
from tactile_flow.runstore import RunStore, open_run
from tactile_flow.runstore.recover import recover

PROBES = ("inlet", "outlet", "ambient")


@dataclass(frozen=True)
class ThermoSample:
    """One reading of a three-probe thermometer: ``temperature_c`` (degC, the mean) and
    ``probes`` (3,) degC, stamped by its own clock (``device_time``, s)."""

    host_time: float
    device_time: float
    temperature_c: float
    probes: np.ndarray

    @classmethod
    def describe(cls) -> tuple[Stream, ...]:
        T, TP = ("time_thermo",), ("time_thermo", "probe")
        return (Stream("thermo", "thermo", "time_thermo", "thermometer", rate_hz=50.0,
                       device_time=device_time("device_time", "time_thermo", "thermometer clock (s)"),
                       columns=(Column("temperature", T, "f8", "degC", "mean temperature", "temperature_c"),
                                Column("probe_temperature", TP, "f8", "degC", "temperature per probe", "probes")),
                       coords=(Coord("probe", PROBES, "", "thermometer probe"),)),)


class Thermometer:
    """A device producing :class:`ThermoSample` at ``rate_hz`` on the host clock; its own clock
    runs 12 s ahead of the host's."""

    def __init__(self, clock, rate_hz: float = 50.0):
        self.clock, self.period = clock, 1.0 / rate_hz
        self._next = clock.now()
        self._n = 0
        self._lock = threading.Lock()

    def read_samples(self) -> list[ThermoSample]:
        out = []
        with self._lock:
            while self._next <= self.clock.now():
                t, k = self._next, self._n
                probes = np.array([20.0 + 0.01 * k, 30.0 - 0.01 * k, 21.5])
                out.append(ThermoSample(t, t + 12.0, float(probes.mean()), probes))
                self._next += self.period
                self._n += 1
        return out


def test_a_declared_stream_is_recorded_and_read_back(tmp_path):
    clock = WallClock()
    store = RunStore.create(tmp_path / "run.zarr", protocol="toy", streams={s.name: s for s in ThermoSample.describe()})
    thermo = Thermometer(clock)
    rec = Recorder(store, {"thermo": thermo.read_samples}, clock, flush_interval_s=0.2).start()
    clock.sleep(0.8)
    rec.stop("success")

    dt = open_run(store.path)
    assert dt.attrs["status"] == "success"
    ds = dt["thermo"].to_dataset()
    n = ds.sizes["time_thermo"]
    assert n >= 30                                               # 0.8 s at 50 Hz
    assert ds["probe"].values.tolist() == list(PROBES)
    assert ds["probe_temperature"].dims == ("time_thermo", "probe")
    assert ds["temperature"].attrs["units"] == "degC" and ds["time_thermo"].attrs["units"] == "s"
    k = np.arange(n)
    np.testing.assert_allclose(ds["probe_temperature"].values[:, 0], 20.0 + 0.01 * k)
    np.testing.assert_allclose(ds["temperature"].values, ds["probe_temperature"].values.mean(axis=1))
    # the clock model maps the device clock (12 s ahead) onto the run's time base
    t = ds["time_thermo"].values
    assert np.all(np.diff(t) > 0)
    np.testing.assert_allclose(t, ds["host_time"].values, atol=0.02)
    host = ds["host_time"].values + dt.attrs["t0_clock_s"]          # raw host clock
    np.testing.assert_allclose(ds["device_time"].values - host, 12.0, atol=1e-6)
    assert dt["thermo"].attrs["stream"]["samples"] == n


def test_recovery_finds_the_declared_stream_s_time(tmp_path):
    stream = ThermoSample.describe()[0]
    store = RunStore.create(tmp_path / "run.zarr", protocol="toy", streams={"thermo": stream})
    clock = iter(np.arange(0.0, 100.0, 0.5))
    samples = [ThermoSample(t, t, 20.0, np.full(3, 20.0)) for t in (next(clock) for _ in range(8))]

    def rows(batch):
        cols = stream.to_columns(batch)
        cols["time_thermo"] = cols["host_time"]
        return cols

    store.append("thermo", rows(samples[:5]))
    store.commit()                                              # published: up to 2.0 s
    store.append("thermo", rows(samples[5:]))                   # never committed: the crash
    result = recover(store.path)
    assert result["status"] == "crashed"
    assert result["last_sample_s"] == 2.0
    assert result["trimmed"]["thermo/time_thermo"] == 3
    assert open_run(store.path)["thermo"].sizes["time_thermo"] == 5
