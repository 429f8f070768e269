"""Protocols: Hydra configs expanded into a checked plan (:mod:`.plan`, :mod:`.steps`) and run on
a lab by the run engine (:mod:`.engine`) while the recorder (:mod:`.recorder`) writes the run
store; :mod:`.cli` is ``tactile-run``. See docs/architecture.md and docs/protocols.md."""
