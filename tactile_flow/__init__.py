"""tactile-flow: computational tactile flow for a UR10 + Shadow Hand + BioTac fingertips, and the
framework that runs its experiments.

The one import name the distribution installs. The repository's folders are its subpackages
(``pyproject.toml`` maps them): ``tactile_flow.tactile`` (the method), ``.hardware``,
``.runstore``, ``.protocols``, ``.analysis``, ``.importers``, ``.viewer``, ``.cliapp``,
``.validation``, and ``.conf`` (the Hydra configs, shipped as package data).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("tactile-flow")
except PackageNotFoundError:        # run from a source tree that was never installed
    __version__ = "0+unknown"
