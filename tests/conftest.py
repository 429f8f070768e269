from pathlib import Path

import numpy as np
import pytest

#: the real recordings the tests read (shipped with the project; attribution in DATA / "README.md")
DATA = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory):
    """A geodesic cache shared by the whole test session (built once, like a user's)."""
    return tmp_path_factory.mktemp("tactile-cache")


@pytest.fixture(scope="session")
def model(cache_dir):
    from tactile.pipeline import TactileConfig, TactileModel
    return TactileModel.build(TactileConfig(), cache_dir=cache_dir)


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


class EventLog:
    """The part of the recorder the run engine talks to, kept in memory: events, the run's
    time origin and the recording's health. Engine tests that need no store use it."""

    t0 = 0.0

    def __init__(self):
        self.events = []

    def event(self, kind, name, detail=None):
        self.events.append((kind, name, detail))

    def write_failure(self, max_age_s):
        return None

    def keep_up(self):
        pass

    def kinds(self):
        return [k for k, _, _ in self.events]
