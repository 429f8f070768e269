"""Test boards: configuration (``conf/surface/*.yaml``), features and the height map.

A board is a flat plate whose top surface is centred at ``origin_m`` (robot base frame)
with its local x axis at ``angle_deg`` from the base x axis (about z). ``count`` features
lie across local x, centred, ``spacing_mm`` apart, each running along local y (so a
sweep along local x crosses them one by one). Features are named ``feature_0``,
``feature_1``, ... in order of increasing local x.

Kinds: ``straws`` (cylinders of ``diameter_mm`` lying on the board, proud by their
diameter), ``sticks`` (rectangular bars ``width_mm`` wide and ``height_mm`` high),
``bump`` (spherical caps of ``radius_mm`` footprint and ``height_mm``), ``flat`` (none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from tactile_flow.validation import spec

from .errors import ConfigError

KINDS = ("straws", "sticks", "flat", "bump")


@dataclass
class SurfaceConfig:
    """One board; kind-specific sizes are ignored by the other kinds (mm, deg, m)."""
    kind: str = "straws"
    name: str = ""                        # what the object is called in the ground truth (default: kind)
    count: int = 3
    spacing_mm: float = 20.0
    angle_deg: float = 0.0
    origin_m: list[float] = field(default_factory=lambda: [0.3, 0.0, 0.05])
    board_size_mm: list[float] = field(default_factory=lambda: [200.0, 150.0])
    length_mm: float = 100.0              # feature length along local y
    diameter_mm: Optional[float] = 6.0    # straws
    width_mm: Optional[float] = 10.0      # sticks
    height_mm: Optional[float] = 2.0      # sticks, bump
    radius_mm: Optional[float] = 8.0      # bump footprint radius
    sweep_depth_mm: float = spec(1.5, gt=0)   # how deep a sweep presses the pad below the features' top: a
                                          # board's own (a flat stick top saturates the electrodes at a depth
                                          # a round straw does not); the shipped sweeps take it from here


@dataclass(frozen=True)
class Feature:
    """One feature, SI units (m, rad), positions in the robot base frame.

    ``centre``: (3,) centre of its footprint on the board top; ``width``: extent across
    (local x); ``height``: top above the board; ``length``: extent along (local y);
    ``angle``: direction of its long axis from base x (rad); ``u``: position along the
    board's local x (m).
    """

    index: int
    name: str
    kind: str
    centre: np.ndarray
    width: float
    height: float
    length: float
    angle: float
    u: float


class Surface:
    """A board and its features, with a vectorised height map.

    ``height(x, y)`` (m, any broadcastable shapes) is the top of the board + features,
    ``-inf`` off the board. ``height_and_feature`` also returns which feature is on top
    (index, -1 for the bare board).
    """

    def __init__(self, cfg: SurfaceConfig, features: list[Feature]):
        self.cfg = cfg
        self.kind = cfg.kind
        self.features = features
        self.origin = np.asarray(cfg.origin_m, float)
        self.angle = math.radians(cfg.angle_deg)
        self._c, self._s = math.cos(self.angle), math.sin(self.angle)
        self.half = np.asarray(cfg.board_size_mm, float) / 2000.0
        self.top_z = float(self.origin[2])
        self.max_z = self.top_z + max((f.height for f in features), default=0.0)
        self._u = np.array([f.u for f in features])
        self._hw = np.array([f.width / 2 for f in features])
        self._hl = np.array([f.length / 2 for f in features])
        self._h = np.array([f.height for f in features])

    # board frame ---------------------------------------------------------------------
    def to_board(self, x, y):
        """Base-frame (x, y) → board-local (u across, w along), m."""
        dx, dy = np.asarray(x) - self.origin[0], np.asarray(y) - self.origin[1]
        return dx * self._c + dy * self._s, -dx * self._s + dy * self._c

    @property
    def across(self) -> np.ndarray:
        """(3,) unit vector of the board's local x (across the features) in the base frame."""
        return np.array([self._c, self._s, 0.0])

    def feature(self, name_or_index) -> Feature:
        """A feature by name (``"feature_1"``) or index; KeyError listing the names otherwise."""
        for f in self.features:
            if name_or_index == f.name or name_or_index == f.index:
                return f
        raise KeyError(f"surface {self.kind!r} has no feature {name_or_index!r}; "
                       f"it has {[f.name for f in self.features] or 'none'}")

    # height map ----------------------------------------------------------------------
    def height_and_feature(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Height (m, base frame z) and top feature index (-1: board) at points (x, y)."""
        u, w = self.to_board(x, y)
        u, w = np.atleast_1d(u), np.atleast_1d(w)
        on_board = (np.abs(u) <= self.half[0]) & (np.abs(w) <= self.half[1])
        base = np.where(on_board, self.top_z, -np.inf)
        if not self.features:
            return base, np.full(base.shape, -1)
        du = u[..., None] - self._u                                   # (..., K)
        inside = np.abs(w)[..., None] <= self._hl
        if self.kind == "straws":
            r = self._hw
            h = r + np.sqrt(np.maximum(r * r - du * du, 0.0))
            h = np.where((np.abs(du) < r) & inside, h, 0.0)
        elif self.kind == "sticks":
            h = np.where((np.abs(du) <= self._hw) & inside, self._h, 0.0)
        else:  # bump: spherical cap of footprint radius a and height h
            a, hc = self._hw, self._h
            R = (a * a + hc * hc) / (2 * hc)
            wc = w[..., None]
            rho2 = du * du + wc * wc
            h = np.where(rho2 < a * a, np.sqrt(np.maximum(R * R - rho2, 0.0)) - (R - hc), 0.0)
        k = np.argmax(h, axis=-1)
        top = h.max(axis=-1)                                          # h at k
        idx = np.where((top > 0) & on_board, k, -1)
        return base + np.where(on_board, top, 0.0), idx

    def height(self, x, y) -> np.ndarray:
        return self.height_and_feature(x, y)[0]

    def describe(self) -> dict:
        """Feature table as plain arrays (for the ground truth and the protocols)."""
        fs = self.features
        return {"kind": self.kind,
                "name": np.array([f.name for f in fs], dtype=str),
                "centre_m": np.array([f.centre for f in fs]).reshape(-1, 3),
                "width_m": np.array([f.width for f in fs]),
                "height_m": np.array([f.height for f in fs]),
                "length_m": np.array([f.length for f in fs]),
                "angle_rad": np.array([f.angle for f in fs])}


def load_surface(data=None, key: str = "surface") -> Surface:
    """Validate a surface config (dict / OmegaConf / SurfaceConfig) and build the :class:`Surface`.

    Raises ConfigError (a ValueError) naming the key for an unknown kind, non-positive
    sizes, overlapping features, or features that do not fit on the board.
    """
    from tactile_flow.validation import build
    cfg = data if isinstance(data, SurfaceConfig) else build(SurfaceConfig, data, key)
    if cfg.kind not in KINDS:
        raise ConfigError(f"{key}.kind", f"unknown surface {cfg.kind!r}; expected one of {', '.join(KINDS)}")
    if len(cfg.origin_m) != 3:
        raise ConfigError(f"{key}.origin_m", f"expected [x, y, z] (m), got {cfg.origin_m}")
    if len(cfg.board_size_mm) != 2 or min(cfg.board_size_mm) <= 0:
        raise ConfigError(f"{key}.board_size_mm", f"expected two sizes > 0 (mm), got {cfg.board_size_mm}")
    if cfg.kind == "flat":
        return Surface(cfg, [])
    if cfg.count < 1:
        raise ConfigError(f"{key}.count", f"expected at least 1 feature, got {cfg.count}")
    if cfg.spacing_mm <= 0 and cfg.count > 1:
        raise ConfigError(f"{key}.spacing_mm", f"expected a spacing > 0 (mm), got {cfg.spacing_mm}")
    if cfg.length_mm <= 0:
        raise ConfigError(f"{key}.length_mm", f"expected a length > 0 (mm), got {cfg.length_mm}")
    need = {"straws": ["diameter_mm"], "sticks": ["width_mm", "height_mm"],
            "bump": ["radius_mm", "height_mm"]}[cfg.kind]
    for n in need:
        v = getattr(cfg, n)
        if v is None or not v > 0:
            raise ConfigError(f"{key}.{n}", f"expected a size > 0 (mm) for {cfg.kind}, got {v!r}")
    mm = 1e-3
    if cfg.kind == "straws":
        width = height = cfg.diameter_mm * mm
        wkey = "diameter_mm"
    elif cfg.kind == "sticks":
        width, height, wkey = cfg.width_mm * mm, cfg.height_mm * mm, "width_mm"
    else:
        width, height, wkey = 2 * cfg.radius_mm * mm, cfg.height_mm * mm, "radius_mm"
        if cfg.height_mm > cfg.radius_mm:
            raise ConfigError(f"{key}.height_mm", f"a bump cap cannot be higher ({cfg.height_mm} mm) "
                                                  f"than its footprint radius ({cfg.radius_mm} mm)")
    spacing = cfg.spacing_mm * mm
    if cfg.count > 1 and spacing < width:
        raise ConfigError(f"{key}.spacing_mm", f"features overlap: spacing {cfg.spacing_mm} mm is less "
                                               f"than their width ({key}.{wkey} → {width / mm:g} mm)")
    extent = (cfg.count - 1) * spacing + width
    if extent > cfg.board_size_mm[0] * mm:
        raise ConfigError(f"{key}.count", f"{cfg.count} features {cfg.spacing_mm} mm apart span "
                                          f"{extent / mm:g} mm, more than the board ({key}.board_size_mm[0] "
                                          f"= {cfg.board_size_mm[0]} mm)")
    length = cfg.length_mm * mm if cfg.kind != "bump" else width
    if length > cfg.board_size_mm[1] * mm:
        raise ConfigError(f"{key}.length_mm", f"features ({length / mm:g} mm) longer than the board "
                                              f"({key}.board_size_mm[1] = {cfg.board_size_mm[1]} mm)")
    ang = math.radians(cfg.angle_deg)
    across = np.array([math.cos(ang), math.sin(ang), 0.0])
    origin = np.asarray(cfg.origin_m, float)
    feats = []
    for i in range(cfg.count):
        u = (i - (cfg.count - 1) / 2) * spacing
        feats.append(Feature(index=i, name=f"feature_{i}", kind=cfg.kind, centre=origin + u * across,
                             width=width, height=height, length=length,
                             angle=ang + math.pi / 2, u=u))
    return Surface(cfg, feats)
