"""The figures of every default protocol: no text overprints another, arrows drawn to scale.

Each protocol runs on the simulated lab (``tactile-run analyze=false`` in a subprocess, real
run stores); its analysis is computed in process and every figure is drawn with Agg, then
every visible text's extent is compared with every other's (matplotlib reports them)."""

import itertools
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.text import Annotation, Text

from tactile_flow.analysis import figures
from tactile_flow.analysis.config import load_config
from tactile_flow.analysis.load import load_run
from tactile_flow.analysis.pipeline import analyse, get_model

pytestmark = pytest.mark.slow
BIN = Path(sys.executable).parent
PROTOCOLS = ("straws_sweep", "sticks_sweep", "pour_grasp", "pour_grasp_reactive")


@pytest.fixture(scope="module", params=PROTOCOLS)
def drawn(request, tmp_path_factory):
    """(protocol, [(name, Figure drawn on an Agg canvas)], analysis, model)."""
    d = tmp_path_factory.mktemp(request.param)
    env = dict(os.environ, TACTILE_CACHE_DIR=os.environ.get("TACTILE_CACHE_DIR", str(d / "cache")))
    r = subprocess.run([str(BIN / "tactile-run"), f"protocol={request.param}", "analyze=false", "progress=false",
                        f"hydra.run.dir={d / 'run'}"], cwd=d, capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    cfg = load_config({"progress": False})
    model = get_model(cfg.tactile)
    a = analyse(load_run(d / "run" / "run.zarr"), cfg, model)
    figs, left_out = figures.build_all(a, model, cfg)
    assert not left_out
    texts = {name: _drawn_texts(fig) for name, fig in figs}
    return request.param, figs, a, model, texts


def _drawn_texts(fig) -> list:
    """(text, window extent) of every text the Agg canvas actually draws (tick labels outside
    the view are not drawn, though they exist as Text objects)."""
    out, draw = [], Text.draw

    def recording(self, renderer):
        draw(self, renderer)
        if self.get_visible() and self.get_text().strip():
            out.append((self.get_text(), self.get_window_extent(renderer)))

    Text.draw = recording
    try:
        FigureCanvasAgg(fig).draw()
    finally:
        Text.draw = draw
    return out


def test_no_text_overlaps_and_all_inside(drawn):
    protocol, figs, _, _, drawn_texts = drawn
    expected = {"electrodes.png", "pressure.png", "taxels.png", "ellipsoid.png"}
    assert expected <= {n for n, _ in figs} and any(n.startswith("flow_") for n, _ in figs)
    for name, fig in figs:
        texts = drawn_texts[name]
        w, h = fig.canvas.get_width_height()
        for text, box in texts:
            assert box.x0 >= -1 and box.y0 >= -1 and box.x1 <= w + 1 and box.y1 <= h + 1, \
                f"{protocol} {name}: {text!r} leaves the figure ({box})"
        for (t1, b1), (t2, b2) in itertools.combinations(texts, 2):
            dx = min(b1.x1, b2.x1) - max(b1.x0, b2.x0)
            dy = min(b1.y1, b2.y1) - max(b1.y0, b2.y0)
            assert not (dx > 1 and dy > 1), f"{protocol} {name}: {t1!r} overlaps {t2!r}"


def test_flow_arrows_to_scale(drawn):
    """The aggregated-flow arrow is as long as its flow (px/frame) over the figure's scale, and
    absent where that flow is below the noise."""
    protocol, figs, a, model, _ = drawn
    arrows = 0
    for name, fig in figs:
        if not name.startswith("flow_"):
            continue
        for ann in fig.findobj(Annotation):
            gid = ann.get_gid() or ""
            if not gid.startswith("aggregate:"):
                continue
            px = float(gid.split(":", 1)[1])
            assert px >= model.config.noise
            length = np.hypot(*(np.asarray(ann.xy) - np.asarray(ann.xyann)))
            assert length == pytest.approx(px / fig.flow_scale, rel=1e-6), (protocol, name)
            arrows += 1
    if protocol.endswith("_sweep"):      # a held bottle's pattern may stay below the noise throughout
        assert arrows > 0, protocol
