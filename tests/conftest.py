import numpy as np
import pytest


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
