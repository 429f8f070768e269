"""A time-synchronised viewer of runs (Rerun): ``tactile-view RUN_DIR`` replays a recorded run,
``tactile-run live.viewer=rerun`` streams the live monitor's results during a run.

Modules: :mod:`viewer.scene` (what a run shows, as arrays: no Rerun), :mod:`viewer.draw`
(colours, arrows, poses: pure numpy), :mod:`viewer.record` (a scene into a Rerun recording),
:mod:`viewer.layout` (the viewer's panels), :mod:`viewer.live` (the live viewer),
:mod:`viewer.cli` (``tactile-view``). Rerun (the optional extra ``[view]``) is imported only
by :mod:`viewer.record`, :mod:`viewer.layout` and :mod:`viewer.live`, and only when used.
See docs/viewer.md.
"""

TIMELINE = "time"
"""The one timeline: seconds since run start (the run store's time base), a Rerun duration."""

INSTALL_HINT = "pip install -e '.[view]'"
