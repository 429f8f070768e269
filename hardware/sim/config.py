"""The simulated lab's config moved to :mod:`hardware.config`; re-exported for the simulator's modules."""

from ..config import *  # noqa: F401,F403
from ..config import (ArmConfig, ContactConfig, FaultsConfig, HandConfig, PourConfig, PumpConfig,  # noqa: F401
                      ScaleConfig, SensorModelConfig, SimConfig, StageConfig, WorkspaceConfig, load_config,
                      validate)
from tactile_flow.validation import build, to_plain  # noqa: F401
