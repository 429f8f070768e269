"""The Hydra configs (protocols, surfaces, hardware, analysis, experiments), shipped inside the
package as ``tactile_flow.conf``; ``DIR`` is where they are, in a checkout or an installed wheel."""

from pathlib import Path

DIR = Path(__file__).resolve().parent
