"""The affordance gradient as numpy arrays over the estimator's published grids.

`Gradient.predict(contact_deg, alpha_deg)` answers as the Rust planner's
`AffordanceGradient::predict` on the gradient it rebuilds from the same grids
(libs/affordance: f32 cells, f32 bilinear weights, the weighted sums as mean x weight),
at the aim point `aim_point(contact_deg)` (libs/planning `aim_point_at`: the ray from the
centroid at that angle meets the learned border). python/tests/test_gradient.py holds it
to `agp-py-reference predict` within 1e-6.
"""

from __future__ import annotations

import ctypes
import math
from typing import Iterable, NamedTuple

import numpy as np

from .payloads import (
    GRID_CELLS,
    GRID_DISPLACEMENT_SQ_MEAN,
    GRID_POSITION_X,
    GRID_POSITION_Y,
    GRID_PUSH_WEIGHT,
    GRID_ROTATION,
    GRID_ROTATION_SQ_MEAN,
    GRID_SHAPE,
    GRID_SIDE,
    GRIDS_PER_ALPHA,
    GradientGrid,
    GridHeader,
)

MIN_PREDICTION_EVIDENCE = 0.005
CONTACT_BORDER_THRESHOLD = np.float32(0.3)
ALPHA_EPS_DEG = 1e-6
_F0, _F1 = np.float32(0.0), np.float32(1.0)
_HEADER_BYTES = ctypes.sizeof(GridHeader)
_MEANS = (GRID_POSITION_X, GRID_POSITION_Y, GRID_DISPLACEMENT_SQ_MEAN, GRID_ROTATION, GRID_ROTATION_SQ_MEAN)


class Prediction(NamedTuple):
    """What a push is predicted to do, in the object's frame before the push."""

    dx_mm: float
    dy_mm: float
    dtheta_deg: float
    #: The weighted spread of the displacements that went into it, mm.
    spread_mm: float
    rotation_spread_deg: float
    #: 1 - exp(-w), w the interpolated push weight.
    confidence: float


class Layer:
    """One learned alpha: the grids a prediction reads, as (128, 128)-shaped float32 arrays
    (row j along y), and the weighted sums (mean x weight) it interpolates."""

    def __init__(self, alpha_deg: float, grids: dict[int, np.ndarray], shape_scale: float):
        self.alpha_deg = alpha_deg
        self.grids = grids
        w = grids[GRID_PUSH_WEIGHT]
        self.weight = w
        # As the Rust rebuild: each weighted sum is its mean times its weight, in f32.
        self.sums = {k: grids[k] * w for k in _MEANS}
        self.shape_evidence = grids[GRID_SHAPE] * np.float32(shape_scale)


def _bilinear(cx: float, cy: float):
    """The cells and f32 weights of a bilinear sample at cell coordinates (cx, cy), as
    `Grid::bilinear`: None when no cell is touched; a corner off the grid weighs 0."""
    side = GRID_SIDE
    if not (cx > -1.0 and cy > -1.0 and cx < side and cy < side):
        return None
    fx0, fy0 = math.floor(cx), math.floor(cy)
    fx, fy = np.float32(cx - fx0), np.float32(cy - fy0)
    corners = (
        (fx0, fy0, (_F1 - fx) * (_F1 - fy)),
        (fx0 + 1, fy0, fx * (_F1 - fy)),
        (fx0, fy0 + 1, (_F1 - fx) * fy),
        (fx0 + 1, fy0 + 1, fx * fy),
    )
    out = []
    for i, j, w in corners:
        if 0 <= i < side and 0 <= j < side:
            out.append((j * side + i, w))
        else:
            out.append((0, _F0))
    return out


def _apply(b, flat: np.ndarray) -> np.float32:
    """w0 c0 + w1 c1 + w2 c2 + w3 c3 in f32, in that order (`Bilinear::apply`)."""
    (i0, w0), (i1, w1), (i2, w2), (i3, w3) = b
    return w0 * flat[i0] + w1 * flat[i1] + w2 * flat[i2] + w3 * flat[i3]


class Gradient:
    """The affordance gradient of one published grid set (every kind of every alpha).

    Build it with `Gradient.from_buffers` (any buffers holding `GradientGrid`s: a file of
    them, or the samples of `agp/grids`). Layers are in ascending alpha; `alphas_deg` lists
    them. The grids are numpy views over the buffers given (no copy); `agp.run` hands the
    planner one over the loaned samples of `agp/grids` themselves, which the gradient holds
    (`hold`) for as long as it lives."""

    def __init__(self, layers: list[Layer], cell_size_m: float, origin_m: tuple[float, float], seq: int):
        if not layers:
            raise ValueError("a gradient needs at least one alpha")
        self.layers = sorted(layers, key=lambda l: l.alpha_deg)
        self.cell_size_m = cell_size_m
        self.origin_m = origin_m
        self.seq = seq
        self.alphas_deg = [l.alpha_deg for l in self.layers]
        total = np.zeros(GRID_CELLS, dtype=np.float32)
        for layer in self.layers:
            total += layer.shape_evidence
        peak = max(np.float32(0.0), np.float32(np.nanmax(total)) if total.size else _F0)
        #: S over every alpha, normalised to [0, 1] (`combined_shape`), flat.
        self.shape = total * (_F1 / peak) if peak > 0 else np.zeros_like(total)
        self._aims: dict[float, tuple[float, float] | None] = {}
        self._held: object = None

    def hold(self, owner: object) -> None:
        """Keeps `owner` (what owns the memory the grids are views of: loaned samples and
        their subscriber) alive as long as this gradient."""
        self._held = owner

    @classmethod
    def from_buffers(cls, buffers: Iterable) -> "Gradient":
        """From buffers (bytes-like, each one `GradientGrid`) of one complete set."""
        grids: dict[float, dict[int, np.ndarray]] = {}
        scales: dict[float, float] = {}
        geometry = None
        for buf in buffers:
            mv = memoryview(buf).cast("B")
            h = GridHeader.from_buffer_copy(mv[:_HEADER_BYTES])
            cells = np.frombuffer(mv, dtype=np.float32, count=GRID_CELLS, offset=_HEADER_BYTES)
            grids.setdefault(h.alpha_deg, {})[h.kind] = cells
            if h.kind == GRID_SHAPE:
                scales[h.alpha_deg] = h.shape_scale
            geometry = (h.cell_size_m, (h.origin_x_m, h.origin_y_m), h.seq, h.alpha_count)
        if geometry is None:
            raise ValueError("no grids")
        cell, origin, seq, count = geometry
        missing = [a for a, g in grids.items() if len(g) < GRIDS_PER_ALPHA]
        if len(grids) != count or missing:
            raise ValueError(f"an incomplete grid set: {len(grids)} of {count} alphas, alphas {missing} lack kinds")
        layers = [Layer(a, g, scales[a]) for a, g in grids.items()]
        return cls(layers, cell, origin, seq)

    @classmethod
    def from_file(cls, path: str) -> "Gradient":
        """From a file of `GradientGrid`s, one after another (`agp-py-reference grids`),
        mapped, not read."""
        size = ctypes.sizeof(GradientGrid)
        data = np.memmap(path, dtype=np.uint8, mode="r")
        return cls.from_buffers(data[k * size : (k + 1) * size] for k in range(len(data) // size))

    # -- geometry ------------------------------------------------------------------------------

    def _cell_coords(self, x: float, y: float) -> tuple[float, float]:
        return (x - self.origin_m[0]) / self.cell_size_m - 0.5, (y - self.origin_m[1]) / self.cell_size_m - 0.5

    def sample_shape(self, x: float, y: float) -> float:
        """The combined S at (x, y), object frame (m): bilinear, 0 off the grid."""
        b = _bilinear(*self._cell_coords(x, y))
        return _F0 if b is None else _apply(b, self.shape)

    def aim_point(self, contact_deg: float) -> tuple[float, float] | None:
        """Where the ray from the centroid at `contact_deg` (object frame) meets the learned
        border, m: the centroid of the first band of S above 0.3 walking in from the grid's
        edge (`aim_point_at`). None when the ray meets no border."""
        key = float(contact_deg)
        if key in self._aims:
            return self._aims[key]
        a = math.radians(key)
        ux, uy = math.cos(a), math.sin(a)
        step = 0.25 * self.cell_size_m
        r = 0.5 * GRID_SIDE * self.cell_size_m - self.cell_size_m
        s = self.sample_shape(ux * r, uy * r)
        while r > 0.0 and s < CONTACT_BORDER_THRESHOLD:
            r -= step
            s = self.sample_shape(ux * r, uy * r)
        weight = moment = 0.0
        while r > 0.0 and s >= CONTACT_BORDER_THRESHOLD:
            w = float(s - CONTACT_BORDER_THRESHOLD)
            weight += w
            moment += w * r
            r -= step
            s = self.sample_shape(ux * r, uy * r)
        out = (ux * (moment / weight), uy * (moment / weight)) if weight > 0.0 else None
        self._aims[key] = out
        return out

    # -- predictions ---------------------------------------------------------------------------

    def _layer_predict(self, layer: Layer, x: float, y: float):
        b = _bilinear(*self._cell_coords(x, y))
        if b is None:
            return None
        w = float(_apply(b, layer.weight))
        if w < MIN_PREDICTION_EVIDENCE:
            return None
        s = layer.sums
        dx = float(_apply(b, s[GRID_POSITION_X])) / w
        dy = float(_apply(b, s[GRID_POSITION_Y])) / w
        dvar = float(_apply(b, s[GRID_DISPLACEMENT_SQ_MEAN])) / w - (dx * dx + dy * dy)
        rot = float(_apply(b, s[GRID_ROTATION])) / w
        rvar = float(_apply(b, s[GRID_ROTATION_SQ_MEAN])) / w - rot * rot
        return [dx, dy, rot, 1.0 - math.exp(-w), math.sqrt(max(dvar, 0.0)), math.sqrt(max(rvar, 0.0))]

    def predict_at(self, x: float, y: float, alpha_deg: float) -> Prediction | None:
        """The push with aim point (x, y) (object frame, m) at `alpha_deg`, as
        `AffordanceGradient::predict`: a learned alpha's layer, else linear between the two
        learned alphas round it (one side only: its answer, confidence scaled)."""
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(alpha_deg)):
            return None
        first, last = self.layers[0].alpha_deg, self.layers[-1].alpha_deg
        if alpha_deg < first - ALPHA_EPS_DEG or alpha_deg > last + ALPHA_EPS_DEG:
            return None
        p = None
        for layer in self.layers:
            if abs(layer.alpha_deg - alpha_deg) < ALPHA_EPS_DEG:
                p = self._layer_predict(layer, x, y)
                break
        else:
            hi = next(k for k, l in enumerate(self.layers) if l.alpha_deg > alpha_deg)
            a, b = self.layers[hi - 1], self.layers[hi]
            t = (alpha_deg - a.alpha_deg) / (b.alpha_deg - a.alpha_deg)
            pa, pb = self._layer_predict(a, x, y), self._layer_predict(b, x, y)
            if pa is not None and pb is not None:
                p = [u + (v - u) * t for u, v in zip(pa, pb)]
            elif pa is not None:
                p = pa[:3] + [pa[3] * (1.0 - t)] + pa[4:]
            elif pb is not None:
                p = pb[:3] + [pb[3] * t] + pb[4:]
        if p is None:
            return None
        dx, dy, rot, conf, dspread, rspread = p
        return Prediction(dx * 1e3, dy * 1e3, math.degrees(rot), dspread * 1e3, math.degrees(rspread), conf)

    def prediction(self, contact_deg: float, alpha_deg: float) -> Prediction | None:
        """Everything `predict` knows of the push at `contact_deg`, `alpha_deg`."""
        aim = self.aim_point(contact_deg)
        return None if aim is None else self.predict_at(aim[0], aim[1], alpha_deg)

    def predict(self, contact_deg: float, alpha_deg: float) -> tuple[float, float, float, float] | None:
        """(dx_mm, dy_mm, dtheta_deg, spread_mm) of the push aimed at `contact_deg` (object
        frame) with deviation `alpha_deg`, in the object's frame before the push; None where
        the gradient has no evidence (or the ray meets no border)."""
        p = self.prediction(contact_deg, alpha_deg)
        return None if p is None else (p.dx_mm, p.dy_mm, p.dtheta_deg, p.spread_mm)
