"""The ball's apparent radius over the image, from the camera, once per video.

Under perspective the ball's image grows towards the camera and with a
pincushion lens towards the corners: 8.8 to 18 px over the table at 1.5 m,
15 degrees, k1 +0.25 (1280 x 720), where the image centre's radius is 8.7.
The search's matched filter, the background learner's "a ball fits here"
rules and the moments start window are sized by the ball where it is, not
by that one radius (a box filter sized for 8.7 px inside a 14-px ball peaks
on the ball's rim, twice: the resting ball was reported as two blobs).

:class:`RadiusMap` holds the radius on a coarse grid of pixels (the
equal-area radius of the camera's silhouette there,
:meth:`~cuespin.physics.camera.Camera.ball_outline`), interpolated
bilinearly, and splits the image into bands of a few radii
(``SCALE_RATIO`` apart) for filters that need one size per call.  A
similarity camera (the top-down default) gets one radius everywhere and one
band, so everything sized by it is what it was with a single radius.

Pure functions of the camera; no video I/O.
"""

from __future__ import annotations

import numpy as np

from cuespin.track.outline import is_similarity

# Grid step (px) of the radius map.  The radius changes by at most ~0.3% per
# px (1.5 m, 15 degrees, k1 +0.25, near the camera; track.outline), so over a
# 32-px cell bilinear interpolation is off by well under 1% (a box filter's
# size is rounded to odd pixels anyway).
GRID_PX = 32
# Adjacent search scales differ by this factor in radius: a matched box
# filter of a ball 5% off in radius loses about 10% of its peak (the box is
# 1.4 r wide, its ring 2.8 r; measured on rendered discs) and peaks at the
# ball's centre still; 2x across the image is then 8 scales.
SCALE_RATIO = 1.1
# Vertices of the outline polygons the map is made from (the equal-area
# radius of a 64-gon is corrected for its inscription: exact to 1e-6).
MAP_VERTICES = 64


class RadiusMap:
    """The ball's radius (px) at every pixel of an image.

    Parameters
    ----------
    shape : (int, int)
        Image ``(h, w)``.
    r_centre : float
        The ball's radius at the image centre (px): the radius everywhere
        for a similarity camera, and where the camera cannot say.
    camera : Camera, optional
    R : float, optional
        Ball radius (m).  Without both, or for a similarity camera, the map
        is ``r_centre`` everywhere.
    region : ndarray of bool, shape (h, w), optional
        Where the ball can be (the search mask): the scales cover the radii
        there only (a wide lens's image corners are larger still).
    """

    def __init__(self, shape, r_centre: float, camera=None, R: float | None = None, region=None):
        self.shape = (int(shape[0]), int(shape[1]))
        self.r_centre = float(r_centre)
        h, w = self.shape
        self.constant = camera is None or R is None or is_similarity(camera)
        if self.constant:
            self._grid = None
            self.r_min = self.r_max = self.r_centre
            self.scales = (self.r_centre,)
            self._index = None
            return
        self._gu = np.unique(np.r_[np.arange(0, w, GRID_PX), w - 1]).astype(float)
        self._gv = np.unique(np.r_[np.arange(0, h, GRID_PX), h - 1]).astype(float)
        uu, vv = np.meshgrid(self._gu, self._gv)
        uv = np.c_[uu.ravel(), vv.ravel()]
        xy = np.asarray(camera.to_table(uv), float)
        r = np.full(len(uv), np.nan)
        fin = np.all(np.isfinite(xy), axis=1)
        if fin.any():
            poly = np.asarray(camera.ball_outline(xy[fin], R, MAP_VERTICES), float)
            p = poly - poly.mean(axis=1, keepdims=True)
            q = np.roll(p, -1, axis=1)
            area = 0.5 * np.abs((p[..., 0] * q[..., 1] - q[..., 0] * p[..., 1]).sum(axis=1))
            # The inscribed n-gon's area is sin(2 pi / n) n / (2 pi) of the outline's.
            n = MAP_VERTICES
            area /= np.sin(2 * np.pi / n) * n / (2 * np.pi)
            r[fin] = np.sqrt(area / np.pi)
        r[~np.isfinite(r)] = self.r_centre
        self._grid = r.reshape(len(self._gv), len(self._gu))
        self._image = None
        full = self.image()
        inside = full[region] if region is not None and np.any(region) else full.ravel()
        self.r_min, self.r_max = float(inside.min()), float(inside.max())
        # Scales a factor SCALE_RATIO apart covering [r_min, r_max], centred in it (log).
        n_sc = int(np.ceil(np.log(self.r_max / self.r_min) / np.log(SCALE_RATIO) - 1e-9)) + 1
        mid = 0.5 * (np.log(self.r_min) + np.log(self.r_max))
        self.scales = tuple(float(np.exp(mid + (j - 0.5 * (n_sc - 1)) * np.log(SCALE_RATIO)))
                            for j in range(n_sc))
        self._index = None

    def at(self, uv) -> float:
        """The radius (px) at one pixel position (bilinear in the grid)."""
        if self.constant:
            return self.r_centre
        u, v = float(uv[0]), float(uv[1])
        if not (np.isfinite(u) and np.isfinite(v)):
            return self.r_centre
        row = np.array([np.interp(u, self._gu, g) for g in self._grid])
        return float(np.interp(v, self._gv, row))

    def image(self) -> np.ndarray:
        """The radius at every pixel (px), shape ``(h, w)``, float32."""
        h, w = self.shape
        if self.constant:
            return np.full((h, w), self.r_centre, np.float32)
        if self._image is None:
            Wu = _interp_matrix(np.arange(w, dtype=float), self._gu)
            Wv = _interp_matrix(np.arange(h, dtype=float), self._gv)
            self._image = (Wv @ self._grid @ Wu.T).astype(np.float32)
            self._image.flags.writeable = False
        return self._image

    def scale_of(self, r: float) -> int:
        """Index of the scale nearest ``r`` (in log)."""
        return int(np.argmin(np.abs(np.log(np.asarray(self.scales)) - np.log(max(r, 1e-9)))))

    @property
    def index(self) -> np.ndarray:
        """Per pixel, the index of its nearest scale, shape ``(h, w)``, int8."""
        if self._index is None:
            h, w = self.shape
            if len(self.scales) == 1:
                self._index = np.zeros((h, w), np.int8)
            else:
                edges = np.sqrt(np.asarray(self.scales[:-1]) * np.asarray(self.scales[1:]))
                self._index = np.searchsorted(edges, self.image()).astype(np.int8)
        return self._index

    def bands(self, region=None):
        """``(j, r_j, (v0, v1, u0, u1), mask)`` for every scale that some
        pixel (of ``region``, bool (h, w), if given) takes: its radius, the
        bounding box of its pixels and their mask within it (None: every
        pixel of the image, one scale)."""
        h, w = self.shape
        if len(self.scales) == 1:
            yield 0, self.scales[0], (0, h, 0, w), None
            return
        idx = self.index
        for j, r in enumerate(self.scales):
            on = idx == j
            if region is not None:
                on &= region
            rows, cols = np.flatnonzero(on.any(axis=1)), np.flatnonzero(on.any(axis=0))
            if len(rows) == 0:
                continue
            v0, v1, u0, u1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
            yield j, r, (v0, v1, u0, u1), on[v0:v1, u0:u1]


def _interp_matrix(x: np.ndarray, xp: np.ndarray) -> np.ndarray:
    """Matrix ``W`` with ``W @ f(xp) = np.interp(x, xp, f(xp))`` (linear, clamped)."""
    W = np.zeros((len(x), len(xp)))
    j = np.clip(np.searchsorted(xp, x, side="right") - 1, 0, len(xp) - 2)
    t = np.clip((x - xp[j]) / (xp[j + 1] - xp[j]), 0.0, 1.0)
    W[np.arange(len(x)), j] = 1.0 - t
    W[np.arange(len(x)), j + 1] = t
    return W


def as_radius_map(radius, shape) -> RadiusMap:
    """A :class:`RadiusMap` from a map or from one radius (px) everywhere."""
    return radius if isinstance(radius, RadiusMap) else RadiusMap(shape, float(radius))
