"""The figures' Agg canvas: text where matplotlib's own Agg canvas puts it (within two pixels), PNGs
that read back as drawn."""

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from tactile_flow.analysis import agg_canvas

TEXTS = [  # (x, y, text, keyword arguments): plain, rotated, multi-line, the units' symbols
    (0.05, 0.85, "time since run start (s)", {}),
    (0.05, 0.65, "activation (kΩ) → Σ 12.5°, |flow| 5.60–5.61 mm/s", {"fontsize": 8}),
    (0.05, 0.35, "contact\nthreshold", {"fontsize": 8}),
    (0.85, 0.2, "PDC above rest", {"rotation": 90}),
]


def _ink(canvas_class, text) -> np.ndarray:
    """(rows, cols) bool: where ``text`` alone darkens a white figure, drawn by ``canvas_class``."""
    fig = Figure(figsize=(4, 2), dpi=90)
    x, y, s, kw = text
    fig.text(x, y, s, **kw)
    canvas = canvas_class(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., 0] < 128


def test_text_lands_where_matplotlib_draws_it():
    for text in TEXTS:
        ours, theirs = _ink(agg_canvas.Canvas, text), _ink(FigureCanvasAgg, text)
        box = [np.nonzero(m.any(axis=k))[0][[0, -1]] for m in (ours, theirs) for k in (1, 0)]
        assert np.abs(np.subtract(box[:2], box[2:])).max() <= 2, text[2]     # ink within two pixels
        assert abs(int(ours.sum()) - int(theirs.sum())) <= 0.1 * theirs.sum(), text[2]


def test_png_reads_back_as_drawn(tmp_path):
    rgb = np.random.default_rng(0).integers(0, 256, (37, 53, 3), dtype=np.uint8)
    agg_canvas.write_png(tmp_path / "x.png", rgb, 90)
    with Image.open(tmp_path / "x.png") as im:
        assert im.mode == "RGB" and np.array_equal(np.asarray(im), rgb)
        assert round(im.info["dpi"][0]) == 90


def test_figure_saved_as_drawn(tmp_path):
    fig = Figure(figsize=(3, 2))
    canvas = agg_canvas.Canvas(fig)
    fig.add_subplot().plot([0, 1], [1, 0], label="a line")
    canvas.save_png(tmp_path / "f.png", 90)
    with Image.open(tmp_path / "f.png") as im:
        assert im.size == (270, 180)
        assert np.array_equal(np.asarray(im), np.asarray(canvas.buffer_rgba())[..., :3])


def test_a_figure_is_written_by_matplotlib_when_the_fast_canvas_fails(tmp_path, monkeypatch, caplog):
    """The canvas uses matplotlib's private text API: a matplotlib that changes it costs speed,
    not the figure."""
    from tactile_flow.analysis import figures

    def broken(self, s, prop):
        raise AttributeError("'FontManager' object has no attribute '_find_fonts_by_props'")
    monkeypatch.setattr(agg_canvas.Renderer, "_key", broken)
    fig = figures._figure(3, 2)
    fig.add_subplot().set_xlabel("time since run start (s)")
    figures._save(fig, tmp_path / "f.png")
    with Image.open(tmp_path / "f.png") as im:
        assert im.size == (270, 180)
        assert (np.asarray(im.convert("L")) < 128).any()                   # the label's ink
    assert "fast canvas failed" in caplog.text and "f.png" in caplog.text
