"""An Agg canvas that draws each line of text as one cached bitmap and writes plain PNGs.

matplotlib 3.11's Agg renderer lays out and rasterises text glyph by glyph from Python (about
0.1 ms a character; a flow figure's 1 600 characters were two thirds of its drawing). This
canvas draws a line of plain text as matplotlib 3.10 did, FreeType rendering the whole line
into one bitmap, and keeps that bitmap and the line's measured size until
:func:`clear_text_cache` (``figures.make_all`` calls it after a run's figures): the same label
in the same font (tick labels, legend entries, units) is rasterised once for all of them, and
each font's line heights are read once, not at every layout. Text lands on whole pixels (as in
matplotlib ≤ 3.10) instead of 1/64 px; mathtext and TeX are drawn by matplotlib as before.

:meth:`Canvas.save_png` writes the drawn figure as an 8-bit RGB PNG (the figures are opaque: no
alpha channel), rows unfiltered, zlib level 1: half of Pillow's time for matplotlib's RGBA
(Pillow filters every row adaptively), files of about the same size.
"""

from __future__ import annotations

import math
import struct
import zlib
from functools import lru_cache

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg, get_hinting_flag
from matplotlib.font_manager import fontManager, get_font


@lru_cache(maxsize=4096)
def _line(fonts: tuple[str, ...], size: float, dpi: float, s: str, antialiased: bool):
    """``(width, height, descent)`` in px of the line ``s`` and its (rows, cols) uint8 bitmap
    with its left offset in px."""
    font = get_font(list(fonts))
    font.clear()
    font.set_size(size, dpi)
    font.set_text(s, 0.0, flags=get_hinting_flag())
    w, h = font.get_width_height()
    d = font.get_descent()
    font.draw_glyphs_to_bitmap(antialiased=antialiased)
    image = np.array(font.get_image(), np.uint8)     # a copy: the font's buffer is reused
    return (w / 64, h / 64, d / 64), image, font.get_bitmap_offset()[0] / 64


@lru_cache(maxsize=256)
def _heights(fonts: tuple[str, ...], size: float, dpi: float) -> tuple:
    """``(ascent, descent, line gap)`` in px of a font at ``size`` pt, from its OS/2 or hhea
    table as matplotlib's text layout reads them (it reads the tables at every layout)."""
    font = get_font(list(fonts))
    for table, gap, ascent, descent in (("OS/2", "sTypoLineGap", "sTypoAscender", "sTypoDescender"),
                                        ("hhea", "lineGap", "ascent", "descent")):
        t = font.get_sfnt_table(table)
        if t is not None:
            scale = size * dpi / 72 / font.get_sfnt_table("head")["unitsPerEm"]
            return t[ascent] * scale, -t[descent] * scale, t[gap] * scale
    return None, None, None


def clear_text_cache() -> None:
    """Forget every line kept by :func:`_line` (its bitmaps are a few hundred kB a run)."""
    _line.cache_clear()


class Renderer(RendererAgg):
    """:class:`RendererAgg` whose plain text comes from :func:`_line`."""

    def _key(self, s: str, prop) -> tuple:
        return tuple(fontManager._find_fonts_by_props(prop)), prop.get_size_in_points(), self.dpi, s

    def _get_font_height_metrics(self, prop):
        return _heights(*self._key("", prop)[:3])

    def get_text_width_height_descent(self, s, prop, ismath):
        if ismath:
            return super().get_text_width_height_descent(s, prop, ismath)
        return _line(*self._key(s, prop), True)[0]

    def draw_text(self, gc, x, y, s, prop, angle, ismath=False, mtext=None):
        if ismath:
            return super().draw_text(gc, x, y, s, prop, angle, ismath, mtext)
        (_, _, d), image, xo = _line(*self._key(s, prop), bool(gc.get_antialiased()))
        if image.size == 0:
            return
        a = math.radians(angle)                          # (x, y): the baseline's start, y down
        self._renderer.draw_text_image(image, round(x + xo + d * math.sin(a)), round(y + d * math.cos(a)) + 1,
                                       angle, gc)


class Canvas(FigureCanvasAgg):
    """:class:`FigureCanvasAgg` drawing with :class:`Renderer`."""

    def get_renderer(self):
        w, h = self.get_width_height(physical=True)
        key = w, h, self.figure.dpi
        if self._lastKey != key:
            self.renderer, self._lastKey = Renderer(w, h, self.figure.dpi), key
        return self.renderer

    def save_png(self, path, dpi: float) -> None:
        """Draw the figure at ``dpi`` and write it to ``path`` as an RGB PNG."""
        self.figure.dpi = dpi
        self.draw()
        write_png(path, np.asarray(self.buffer_rgba())[..., :3], dpi)


def write_png(path, rgb: np.ndarray, dpi: float) -> None:
    """Write a (rows, cols, 3) uint8 image as a PNG: unfiltered rows, zlib level 1, its ``dpi``."""
    h, w, _ = rgb.shape
    raw = np.zeros((h, 1 + 3 * w), np.uint8)                  # each row: filter type 0 (none), pixels
    raw[:, 1:] = rgb.reshape(h, 3 * w)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    per_m = round(dpi / 0.0254)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                + chunk(b"pHYs", struct.pack(">IIB", per_m, per_m, 1)) + chunk(b"IDAT", zlib.compress(raw.data, 1))
                + chunk(b"IEND", b""))
