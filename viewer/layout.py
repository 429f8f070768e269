"""The viewer's panels (a Rerun blueprint): tactile frames on the left, time series in the
middle, the arm and fingertips in 3D and the event log on the right, state lanes below.

Only the fingers that touched something get frame panels by default (all of them are in the
recording; add a panel from the viewer's entity tree).
"""

from __future__ import annotations

import rerun.blueprint as rrb

from . import TIMELINE


def frame_grid(fingers, views) -> rrb.Grid:
    """One 2D panel per finger and view (image + flow arrows + direction arrow), a row per finger."""
    return rrb.Grid(*[rrb.Spatial2DView(origin=f"tactile/{f}/{v}", name=f"{f} {v}") for f in fingers for v in views],
                    grid_columns=len(views), name="tactile frames and flow")


def replay(fingers, views, has_pour: bool, has_live: bool) -> rrb.Blueprint:
    """The layout of ``tactile-view``: the frames of the active ``fingers`` (a row each, a column
    per view) beside the arm and the fingertips in 3D; the time series below them; the steps,
    segments and slip state as lanes at the bottom."""
    series = [rrb.TimeSeriesView(origin="signals/pressure", name="pressure above rest"),
              rrb.TimeSeriesView(origin="flow", contents=[f"flow/{f}/{v}/direction" for f in fingers for v in views],
                                 name="flow direction (deg)"),
              rrb.TimeSeriesView(origin="signals/electrodes", contents=[f"signals/electrodes/{f}" for f in fingers],
                                 name="electrodes (counts)")]
    if has_pour:
        series.append(rrb.TimeSeriesView(origin="pour", name="pump and scale"))
    if has_live:
        series.append(rrb.TimeSeriesView(origin="live/magnitude", name="live flow (px/frame)"))
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(frame_grid(fingers, views),
                           rrb.Spatial3DView(origin="world", name="arm and fingertips"),
                           rrb.Spatial3DView(origin="world/tcp", name="fingertips (activation)"),
                           column_shares=[3, 1, 1]),
            rrb.Horizontal(rrb.Grid(*series, grid_columns=2 if len(series) > 3 else 1, name="time series"),
                           rrb.Tabs(rrb.TextLogView(origin="events", name="events"),
                                    rrb.TextDocumentView(origin="run", name="run")),
                           column_shares=[3, 1]),
            lanes(), row_shares=[4, 4, 1.5]),
        rrb.TimePanel(timeline=TIMELINE, expanded=False),
        collapse_panels=True)


def lanes() -> rrb.StateTimelineView:
    return rrb.StateTimelineView(origin="/", contents=["protocol/**", "segments/**", "live/slip"],
                                 name="steps, segments, slip")


def live(fingers, views) -> rrb.Blueprint:
    """The layout of the live viewer (``tactile-run live.viewer=rerun``)."""
    return rrb.Blueprint(
        rrb.Horizontal(
            frame_grid(fingers, views),
            rrb.Vertical(rrb.TimeSeriesView(origin="live/magnitude", name="live flow (px/frame)"),
                         rrb.TimeSeriesView(origin="live/activation_total", name="Σ activation (kΩ)"),
                         lanes(),
                         rrb.TextLogView(origin="events", name="events"))),
        rrb.TimePanel(timeline=TIMELINE, expanded=True),
        collapse_panels=True)
