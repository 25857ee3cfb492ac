"""Drawing frames of a scene: exact-coverage disc, motion blur, noise, 8 bits.

Two looks (``render.look``): ``plain`` (the default) draws grey frames and
``realistic`` colour ones (see :mod:`cuespin.render.look`).  In the plain
look the ball is a disc of uniform grey on a felt background.  Each pixel takes
the exact area of the disc that covers it (no supersampling), so the image's
background-subtracted centroid is the disc's centre to floating-point
precision.  Motion blur averages the coverage over nodes spread across the
exposure; the truth centroid is the mean of the same nodes' centres, so the
two agree exactly.  Only the ball's neighbourhood is drawn per frame: the
rest of the frame is a cached 8-bit background plus integer noise.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from cuespin.physics.contact import scene_trajectory
from cuespin.physics.scene import Scene, motion_end
from cuespin.render import look as lk
from cuespin.render.noise import add_noise
from cuespin.render.timing import frame_times

# Blur nodes are spaced at most this far apart (px) along the path, so the
# blurred streak is smooth; the centroid is exact whatever the spacing.
BLUR_NODE_SPACING_PX = 0.25
MAX_BLUR_NODES = 256
# A homography whose local Jacobian departs from a similarity by more than
# this (relative) would image the ball as an ellipse, which is not modelled.
SIMILARITY_RTOL = 1e-6
# Vertices of the ball's silhouette polygon under a non-similarity camera:
# its centroid is within 1.2e-5 px of the 720-vertex one (measured on a
# 14-px ball, 15 deg tilt, k1 -0.25; tests/test_render.py), its area within 0.05%.
OUTLINE_VERTICES = 128
# Spacing (px) of the grid on which the lens is inverted for the ray map.
RAY_GRID_PX = 8
# Tiles (px) in which the static scene's table parts are skipped when wholly cloth.
LABEL_TILE_PX = 16
# Exposure nodes whose rotations are evaluated in one call (a block of frames):
# 4096 nodes hold 0.3 MB of matrices.
ROTATION_BLOCK_NODES = 4096
# Exposure nodes whose ball windows are computed in one call (a block of
# frames; at most ~1.3 MB of colour on a 14-px ball).
WINDOW_BLOCK_NODES = 64

RENDER_DEFAULTS = {
    "felt_grey": 90.0,        # grey level of the felt
    "ball_grey": 220.0,       # grey level of the ball
    "noise_sigma": 2.0,       # Gaussian sensor noise (grey levels)
    "gradient": 0.0,          # lighting gradient: peak-to-peak grey levels across the frame
    "gradient_angle": 0.0,    # its direction in the image (rad)
    "texture": 0.0,           # static felt texture: standard deviation (grey levels)
    "codec": "MJPG",          # FourCC; FFV1 for lossless
    "duration": None,         # seconds of video; default: until the ball stops or leaves, plus tail
    "tail": 0.25,             # seconds after the ball stops
    "max_duration": 20.0,     # cap (s)
    "seed": 0,                # noise and texture seed
}


def render_settings(scene: Scene) -> dict:
    """The scene's ``render`` block with every default filled in (both looks' keys)."""
    s = dict(RENDER_DEFAULTS)
    # The realistic look's defaults; the keys both looks share (texture,
    # noise_sigma) keep the plain look's defaults in the plain look.
    realistic = scene.render.get("look", "plain") == "realistic"
    s.update({k: v for k, v in lk.LOOK_DEFAULTS.items() if realistic or k not in RENDER_DEFAULTS})
    s.update({k: v for k, v in scene.render.items() if k in s})
    if s["look"] not in ("plain", "realistic"):
        raise ValueError(f"render.look: expected 'plain' or 'realistic', got {s['look']!r}")
    if s["look"] == "realistic":
        lk.check_look(s)
    return s


def ball_motion(scene: Scene):
    """The tracked ball's motion: ``motion(t) -> State`` (x m, v m/s, w rad/s) at times (n,).

    Every position and spin the renderer draws comes from here, so a motion
    with cushion or ball contacts is swapped in on this one line.
    """
    return scene_trajectory(scene).state  # continued past contacts when render.contacts is on


def quadrant_area(x, y, r):
    """Area of the disc ``X^2 + Y^2 <= r^2`` with ``X <= x`` and ``Y <= y``.

    Vectorised over ``x`` and ``y``; exact, from the primitive of the chord
    length.  ``A(x) = int_{-r}^{x} sqrt(r^2 - X^2) dX`` is half the area left
    of ``x``; for ``y >= 0`` the region below ``y`` adds ``min(y, s(X))``.
    """
    # np.minimum / np.maximum rather than np.clip: the same values, without
    # clip's call overhead, which dominated on a tracker's 38 x 38 grid.
    x = np.minimum(np.maximum(x, -r), r)
    y = np.minimum(np.maximum(y, -r), r)
    r2 = r * r

    def A(z):
        return 0.5 * (z * np.sqrt(np.maximum(r2 - z * z, 0.0)) + r2 * np.arcsin(z / r)) + 0.25 * np.pi * r2

    ya = np.abs(y)
    c = np.sqrt(np.maximum(r2 - ya * ya, 0.0))
    # int_{-r}^{x} min(|y|, s(X)) dX, in three pieces split at -c and c.
    # A is evaluated only on x and on c (each varies along one axis of a
    # patch), never on their broadcast: A(min(x, -c)) is A(x) or A(-c).
    Ax, Ac = A(x), A(c)
    m = (np.where(x <= -c, Ax, A(-c)) + ya * (np.minimum(np.maximum(x, -c), c) + c)
         + (np.where(x >= c, Ax, Ac) - Ac))
    upper = Ax + m                   # y >= 0: int (s + min(y, s))
    lower = Ax - m                   # y < 0: the strip X <= x less its part above -y
    return np.where(y >= 0, upper, lower)


def disc_coverage(cu: float, cv: float, r: float, u0: int, v0: int, w: int, h: int) -> np.ndarray:
    """Exact fraction of each pixel covered by a disc, over a ``h x w`` patch.

    Parameters
    ----------
    cu, cv : float
        Disc centre (px, OpenCV convention: pixel (i, j) centred at (j, i)).
    r : float
        Disc radius (px).
    u0, v0 : int
        Column and row of the patch's top-left pixel.
    w, h : int
        Patch width and height (px).

    Returns
    -------
    ndarray, shape (h, w)
        Covered area of each pixel (0 to 1).
    """
    xu = np.arange(u0, u0 + w + 1) - 0.5 - cu
    yv = np.arange(v0, v0 + h + 1) - 0.5 - cv
    G = quadrant_area(xu[None, :], yv[:, None], r)
    return G[1:, 1:] - G[1:, :-1] - G[:-1, 1:] + G[:-1, :-1]


def noise_lut(sigma: float, bits: int = 16) -> np.ndarray:
    """Inverse-CDF table from uniform ``bits``-bit integers to rounded Gaussian noise.

    ``lut[k]`` is the integer ``round(sigma z)`` whose cumulative probability
    bin holds ``(k + 1/2) / 2^bits``, so indexing it with uniform integers
    draws exactly (to 2^-bits) from the law of ``round(sigma z)``.  Adding it
    to an integer image is the same as rounding the noisy float image.
    """
    if sigma <= 0:
        return np.zeros(2**bits, dtype=np.int16)
    kmax = int(math.ceil(8 * sigma)) + 1
    k = np.arange(-kmax, kmax + 1)
    cdf = ndtr((k + 0.5) / sigma)
    p = (np.arange(2**bits) + 0.5) / 2**bits
    return k[np.searchsorted(cdf, p)].astype(np.int16)


class NoiseSampler:
    """Rounded Gaussian noise images, drawn from the law of :func:`noise_lut`
    with one random byte per pixel plus a second only where it matters.

    A 16-bit uniform ``u = 256 hi + lo`` indexes the 16-bit table; in most
    of the 256 blocks of ``hi`` the table is constant, so ``hi`` alone (one
    ``cv2.LUT``) decides, and only pixels whose block holds a step (2-10% at
    sigma 1-8) draw ``lo`` and read the table itself.  The law is exactly
    the table's; the cost is about half the full 16-bit draw.
    """

    def __init__(self, sigma: float):
        # The 16-bit table's values reordered (a uniform index into any
        # ordering of the same values draws the same law) so that each value
        # fills whole blocks first and the leftovers share as few blocks as
        # possible: about half as many mixed blocks as the sorted table.
        vals, counts = np.unique(noise_lut(sigma), return_counts=True)
        pure = np.repeat(vals, counts // 256 * 256)
        rest = np.repeat(vals, counts % 256)
        self.lut = np.concatenate([pure, rest]).astype(np.int16)
        blocks = self.lut.reshape(256, 256)
        self.base = blocks[:, 0].copy().reshape(256, 1)
        self.mixed = (blocks != blocks[:, :1]).any(axis=1).astype(np.uint8).reshape(256, 1)

    def draw(self, rng: np.random.Generator, shape: tuple) -> np.ndarray:
        """Integer noise (int16) of the given shape."""
        import cv2

        n = int(np.prod(shape))
        hi = np.frombuffer(rng.bytes(n), dtype=np.uint8).reshape(shape)
        out = cv2.LUT(hi, self.base) if len(shape) < 3 or shape[2] <= 4 else self.base[hi, 0]
        # nonzero on a bool view: several times faster than on uint8.
        idx = np.nonzero(cv2.LUT(hi, self.mixed).reshape(-1).view(bool))[0]
        if idx.size:
            lo = np.frombuffer(rng.bytes(idx.size), dtype=np.uint8)
            out.reshape(-1)[idx] = self.lut[hi.reshape(-1)[idx].astype(np.int32) * 256 + lo]
        return out


class AliasNoise:
    """Rounded Gaussian noise added to an 8-bit image, drawn from the law of
    :func:`noise_lut` with two random bytes per pixel, in one pass
    (:func:`cuespin.render.noise.add_noise`): the plain look's noise and the
    realistic look's exact law.

    Walker's alias method over the 16-bit table's exact counts: 256 bins of
    256 units, each holding at most two values; the first byte picks the bin
    and the second whether it falls above the bin's threshold, so every
    value's probability is its count / 2^16, exactly the table's law.  Each
    bin keeps its smaller value below the threshold, so the noise is
    ``a[hi] + (lo >= thr[hi]) d[hi]`` with ``d >= 0``, stored offset by 128
    in uint8 (``tables``: the kernel's, unshifted).  About 0.7 ms of CPU a
    1280 x 720 x 3 frame with the compiled kernel (sigma 5; 9.5 ms through
    OpenCV before it, 12.8 with :class:`NoiseSampler`).
    Needs every value in -128..127: ``sigma`` up to :data:`ALIAS_MAX_SIGMA`.
    """

    def __init__(self, sigma: float):
        vals, counts = np.unique(noise_lut(sigma), return_counts=True)
        if vals.min() < -128 or vals.max() > 127:
            raise ValueError(f"noise sigma {sigma} too large for 8-bit alias noise")
        # Vose's construction, padded to 256 items of zero count.
        V = np.zeros(256, int)
        V[:len(vals)] = vals
        c = np.zeros(256, int)
        c[:len(vals)] = counts
        alias = np.arange(256)
        small = [i for i in range(256) if c[i] < 256]
        large = [i for i in range(256) if c[i] >= 256]
        while small and large:
            s, big = small.pop(), large.pop()
            alias[s] = big
            c[big] -= 256 - c[s]
            (small if c[big] < 256 else large).append(big)
        # Bin i: lo < c[i] draws V[i], otherwise V[alias[i]].
        a, b = V.copy(), V[alias]
        a[c == 0] = b[c == 0]
        b[c == 256] = a[c == 256]
        swap = a > b                       # the smaller value below the threshold
        lo_v, hi_v = np.where(swap, b, a), np.where(swap, a, b)
        thr = np.where(lo_v == hi_v, 0, np.where(swap, 256 - c, c))
        self.a = (lo_v + 128).astype(np.uint8).reshape(256, 1)
        self.d = (hi_v - lo_v).astype(np.uint8).reshape(256, 1)
        self.thr = thr.astype(np.uint8).reshape(256, 1)
        # The kernel's tables (cuespin.render.noise): A as int8 bytes, T, D.
        self.tables = np.stack([lo_v.astype(np.int8).view(np.uint8), self.thr[:, 0], self.d[:, 0]])

    def add_to(self, img: np.ndarray, rng: np.random.Generator, out: np.ndarray | None = None) -> np.ndarray:
        """``clip(img + n, 0, 255)`` (uint8) with fresh noise ``n`` per pixel and channel,
        from one 64-bit word of ``rng`` (:func:`cuespin.render.noise.add_noise`)."""
        return add_noise(img, self.tables, int(rng.bit_generator.random_raw()), True, out)


# Largest sigma whose rounded noise (to 8 sigma) fits AliasNoise's -128..127.
ALIAS_MAX_SIGMA = 15.0


class ByteNoise:
    """Rounded Gaussian noise added to an 8-bit image from one random byte per
    pixel and channel: the realistic look's sensor noise.

    The law: 256 equally likely integers, ``noise_lut(s, bits=8)`` (the
    inverse CDF of ``round(s z)`` at the byte's 256 quantiles, so its tails
    stop at 2.9 s: |z| beyond ``Phi^-1(1/512)``), with ``s`` the value in
    0.8-1.3 sigma whose variance is nearest that of ``round(sigma z)`` (the
    exact law :class:`AliasNoise` draws): within 1.4% for sigma 0.5-3 and
    0.5% for 3-40 (``var_ratio``; the standard deviation within half that),
    mean 0, kurtosis 2.8-3.0 (3 for a Gaussian).  A least-squares fit's error and its sandwich errors
    depend on the noise's variance only, so the tracker sees the same noise
    level: on the same realistic FFV1 shots drawn with either law the
    tracker's err/se came out alike (README, Known limits).  Each frame's
    bytes come from a SplitMix64 stream seeded with one word of the caller's
    generator (:mod:`cuespin.render.noise`), so pixels, channels and frames
    are independent and the frames reproducible from the seed.  One compiled
    pass: about 0.3 ms of CPU a 1280 x 720 x 3 frame (2.5 ms through OpenCV
    before it), half :class:`AliasNoise`'s (two bytes a pixel).  Values must fit
    -128..127: sigma from :data:`BYTE_NOISE_SIGMA` [0] to [1].
    """

    def __init__(self, sigma: float):
        target = float(noise_lut(sigma).astype(float).var())
        grid = sigma * np.linspace(0.8, 1.3, 501)
        tabs = [noise_lut(float(g), bits=8) for g in grid]
        var = np.array([t.astype(float).var() for t in tabs])
        i = int(np.argmin(np.abs(var - target) + 1e-9 * np.abs(grid - sigma)))
        table = tabs[i].astype(int)
        if table.min() < -128 or table.max() > 127:
            raise ValueError(f"noise sigma {sigma} too large for byte noise")
        self.sigma = float(sigma)
        self.s = float(grid[i])
        self.table = table
        self.var_ratio = float(var[i] / target)
        self.lut = (table + 128).astype(np.uint8).reshape(256, 1)
        self.tables = np.zeros((3, 256), np.uint8)       # the kernel's: A = table, T = D = 0
        self.tables[0] = table.astype(np.int8).view(np.uint8)

    def add_to(self, img: np.ndarray, rng: np.random.Generator, out: np.ndarray | None = None) -> np.ndarray:
        """``clip(img + n, 0, 255)`` (uint8) with fresh noise ``n`` per pixel and channel,
        from one 64-bit word of ``rng`` (:func:`cuespin.render.noise.add_noise`)."""
        return add_noise(img, self.tables, int(rng.bit_generator.random_raw()), False, out)


# Noise levels drawn as ByteNoise: below 0.5 its 256 atoms match the exact
# law's variance only to 2% (AliasNoise instead); above 40 its tails (2.9 s)
# leave -128..127.
BYTE_NOISE_SIGMA = (0.5, 40.0)
# The realistic look's noise law: "byte" (ByteNoise) or "alias" (AliasNoise,
# the exact law of round(sigma z) to 2^-16, at about five times the CPU).
NOISE_LAW = "byte"


def sensor_noise(sigma: float, law: str | None = None):
    """The realistic look's noise drawer for ``sigma`` (grey levels): an object
    with ``add_to(img, rng)``, or a :class:`NoiseSampler` (``draw``) beyond
    :data:`ALIAS_MAX_SIGMA`."""
    law = NOISE_LAW if law is None else law
    if law == "byte" and BYTE_NOISE_SIGMA[0] <= sigma <= BYTE_NOISE_SIGMA[1]:
        return _noise_drawer(ByteNoise, float(sigma))
    return _noise_drawer(AliasNoise, float(sigma)) if sigma <= ALIAS_MAX_SIGMA else NoiseSampler(sigma)


@functools.lru_cache(maxsize=16)
def _noise_drawer(kind, sigma: float):
    """One drawer (its tables: ~12 ms to build ByteNoise's) per law and sigma in a process."""
    return kind(sigma)


def make_background(scene: Scene, settings: dict) -> np.ndarray:
    """The static 8-bit felt image: flat grey, lighting gradient, texture."""
    cam = scene.camera
    h, w = cam.height, cam.width
    bg = np.full((h, w), float(settings["felt_grey"]), dtype=np.float64)
    if settings["gradient"]:
        a = float(settings["gradient_angle"])
        vv, uu = np.mgrid[0:h, 0:w]
        proj = (uu - (w - 1) / 2) * np.cos(a) + (vv - (h - 1) / 2) * np.sin(a)
        span = max(np.ptp(proj), 1.0)
        bg += float(settings["gradient"]) * proj / span
    if settings["texture"]:
        import cv2
        rng = np.random.default_rng(np.random.SeedSequence([int(settings["seed"]), 7]))
        tex = cv2.GaussianBlur(rng.standard_normal((h, w)), (0, 0), 1.0)
        bg += float(settings["texture"]) * tex / tex.std()
    return np.clip(np.rint(bg), 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class FrameTruth:
    """Truth per frame.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Frame timestamps (s).
    uv : ndarray, shape (n, 2)
        Centroid of the ball's silhouette (px), averaged over the exposure:
        in the plain look, the centroid of the ball's image.
    xy : ndarray, shape (n, 2)
        True ball centre (m) at ``t``.
    uvc : ndarray, shape (n, 2)
        Projection of the true centre (px), averaged over the exposure: what
        the tracker estimates.  Equal to ``uv`` on a top-down camera.
    """

    t: np.ndarray
    uv: np.ndarray
    xy: np.ndarray
    uvc: np.ndarray


def disc_coverage_batch(cu, cv, r: float, u0, v0, n: int) -> np.ndarray:
    """:func:`disc_coverage` of many discs at once, each on its own ``n x n`` window.

    ``cu, cv`` (K,) centres (px), ``u0, v0`` (K,) integer window corners;
    returns shape (K, n, n).
    """
    a = np.arange(n + 1)
    xu = (np.asarray(u0)[:, None] + a - 0.5 - np.asarray(cu)[:, None])[:, None, :]
    yv = (np.asarray(v0)[:, None] + a - 0.5 - np.asarray(cv)[:, None])[:, :, None]
    G = quadrant_area(xu, yv, r)
    return G[:, 1:, 1:] - G[:, 1:, :-1] - G[:, :-1, 1:] + G[:, :-1, :-1]


def polygon_coverage_batch(polys, u0, v0, w: int, h: int) -> np.ndarray:
    """Exact fraction of each pixel covered by simple polygons, one per window.

    The area of the polygon below-left of a grid corner ``(X, Y)`` is
    ``F(X, Y) = sum over edges of  sign * int_{y <= Y} min(x(y) - X, 0) dy``
    (per horizontal line, signed crossings add up to the length of the
    polygon left of X; the X terms cancel), a closed form for straight
    edges.  A pixel's area is ``F``'s second difference over its corners, as
    in :func:`disc_coverage`; along y only the edges inside a pixel row
    differ between its two sides, so the edges are cut where they cross row
    boundaries and each piece adds to its own row.  Exact up to float
    rounding, any orientation, convex or not.

    Parameters
    ----------
    polys : ndarray, shape (K, n, 2)
        Vertices (px) of K polygons, in order around each.
    u0, v0 : ndarray of int, shape (K,)
        Top-left pixel of each window.
    w, h : int
        Window size (px).

    Returns
    -------
    ndarray, shape (K, h, w)
    """
    p = np.asarray(polys, dtype=float)
    K, n = p.shape[:2]
    q = np.roll(p, -1, axis=1)
    area = 0.5 * (p[..., 0] * q[..., 1] - q[..., 0] * p[..., 1]).sum(axis=1)
    p, q = p.reshape(-1, 2), q.reshape(-1, 2)
    node = np.repeat(np.arange(K), n)
    E = len(p)
    y0, y1 = p[:, 1], q[:, 1]
    # Row boundaries y = k - 1/2 strictly inside each edge's span.
    k_lo = np.floor(np.minimum(y0, y1) + 0.5).astype(int) + 1
    k_hi = np.ceil(np.maximum(y0, y1) + 0.5).astype(int) - 1
    cnt = np.maximum(k_hi - k_lo + 1, 0)
    idx = np.repeat(np.arange(E), cnt)
    first = np.cumsum(cnt) - cnt
    kb = k_lo[idx] + np.arange(len(idx)) - first[idx]
    with np.errstate(divide="ignore", invalid="ignore"):
        tb = (kb - 0.5 - y0[idx]) / (y1[idx] - y0[idx])
    T = np.r_[np.zeros(E), tb]
    eid = np.r_[np.arange(E), idx]
    order = np.lexsort((T, eid))
    T, eid = T[order], eid[order]
    T1 = np.r_[T[1:], 1.0]
    last = np.r_[eid[1:] != eid[:-1], True]
    T1[last] = 1.0
    d = q[eid] - p[eid]
    a_pt = p[eid] + T[:, None] * d
    b_pt = p[eid] + T1[:, None] * d
    dy = b_pt[:, 1] - a_pt[:, 1]
    keep = dy != 0
    a_pt, b_pt, dy, nid = a_pt[keep], b_pt[keep], dy[keep], node[eid[keep]]
    row = np.floor(0.5 * (a_pt[:, 1] + b_pt[:, 1]) + 0.5).astype(int) - np.asarray(v0)[nid]
    inside = (row >= 0) & (row < h)
    a_pt, b_pt, dy, nid, row = a_pt[inside], b_pt[inside], dy[inside], nid[inside], row[inside]
    X = np.asarray(u0)[nid][:, None] + np.arange(w + 1) - 0.5                # (M, w+1)
    a, b = a_pt[:, 0:1] - X, b_pt[:, 0:1] - X
    lo_ab = np.minimum(a, b)
    m = np.where(a * b >= 0, 0.5 * (np.minimum(a, 0.0) + np.minimum(b, 0.0)),
                 -(lo_ab * lo_ab) / (2.0 * np.maximum(np.abs(a - b), 1e-300)))
    rowF = np.zeros((K * h, w + 1))
    np.add.at(rowF, nid * h + row, dy[:, None] * m)
    cov = np.diff(rowF.reshape(K, h, w + 1), axis=2)
    # Orientation: the area comes out negative for one sense of traversal.
    return cov * np.sign(area)[:, None, None]


class FrameRenderer:
    """Renders the frames of one scene with its truth.

    Any camera of CONVENTIONS.md: on a top-down (similarity) homography the
    ball is a disc drawn with :func:`disc_coverage`; through any other camera
    (a tilted pose, a lens with distortion) it is the sphere's silhouette,
    the polygon of ``camera.ball_outline`` with ``OUTLINE_VERTICES``
    vertices, drawn with :func:`polygon_coverage_batch`.  Either way the
    coverage is exact, so the truth (the silhouette's centroid, averaged over
    the exposure, area-weighted) is the drawn image's.

    Parameters
    ----------
    scene : Scene
        Must carry ``truth``.
    n_frames : int, optional
        Number of frames; from the scene's motion when absent (see
        :func:`video_length`).
    """

    def __init__(self, scene: Scene, n_frames: int | None = None):
        if scene.truth is None:
            raise ValueError("scene has no truth block: nothing to render")
        self.scene = scene
        self.settings = render_settings(scene)
        self.realistic = self.settings["look"] == "realistic"
        self.cam = scene.camera
        self.H = self.cam.H
        self.motion = ball_motion(scene)
        J = self.cam.jacobian(np.asarray(scene.truth.x0))
        scale = math.sqrt(abs(np.linalg.det(J)))
        self.similar = (not self.cam.has_lens and not self.cam.is_pinhole
                        and np.abs(np.abs(J.T @ J) - scale**2 * np.eye(2)).max()
                        <= SIMILARITY_RTOL * scale**2)
        self._Jinv = np.linalg.inv(J)          # px -> m, constant on a similarity
        self.radius_px = scene.physics.R * scale
        self.n_frames = n_frames if n_frames is not None else video_length(scene)
        self.sigma = float(self.settings["noise_sigma"])
        self.lut = noise_lut(self.sigma)
        self.truth = self._truth()
        if self.realistic:
            self._init_realistic()
        else:
            self.background = make_background(scene, self.settings)
            # The 16-bit table's law through Walker's alias tables, in one pass;
            # past ALIAS_MAX_SIGMA (values beyond int8) the table itself.
            self._plain_noise = (_noise_drawer(AliasNoise, self.sigma) if 0 < self.sigma <= ALIAS_MAX_SIGMA
                                 else None)
            self.felt = float(self.settings["felt_grey"])
            self.ball = float(self.settings["ball_grey"])

    def _scale(self, xy: np.ndarray) -> float:
        """Largest local scale (px per m) over table points ``xy`` (n, 2)."""
        return float(np.sqrt(np.abs(np.linalg.det(self.cam.jacobian(np.atleast_2d(xy))))).max())

    def _nodes(self, t: np.ndarray) -> np.ndarray:
        """Exposure nodes (s) for frames at times ``t``: shape (n, K)."""
        exp = self.cam.exposure_s
        if exp <= 0:
            return t[:, None]
        # Longest blur (px) over these frames decides the node count: the
        # fastest of the exposure's ends and the strike (|v| jumps there).
        probe = np.r_[t - exp / 2, t + exp / 2, self.scene.truth.t0]
        st = self.motion(probe)
        speed = float(np.hypot(*st.v.T).max())
        scale = self.radius_px / self.scene.physics.R if self.similar else self._scale(st.x)
        blur_px = (speed + 1e-9) * exp * scale
        K = int(min(MAX_BLUR_NODES, max(2, math.ceil(blur_px / BLUR_NODE_SPACING_PX))))
        offs = ((np.arange(K) + 0.5) / K - 0.5) * exp
        return t[:, None] + offs[None, :]

    def outlines(self, xy: np.ndarray) -> np.ndarray:
        """The ball's silhouette polygons (px), shape (n, OUTLINE_VERTICES, 2), at centres ``xy``."""
        return self.cam.ball_outline(np.atleast_2d(xy), self.scene.physics.R, OUTLINE_VERTICES)

    def _truth(self) -> FrameTruth:
        t = frame_times(self.scene, self.n_frames).t  # the writer stamps the same times
        nodes = self._nodes(t)
        self._t_nodes = nodes
        xy_nodes = self.motion(nodes.ravel()).x
        uv_nodes = self.cam.to_pixels(xy_nodes).reshape(nodes.shape + (2,))
        self._uv_nodes = uv_nodes
        self._xy_nodes = xy_nodes.reshape(nodes.shape + (2,))
        xy = self.motion(t).x
        uvc = uv_nodes.mean(axis=1)
        if self.similar:
            # Top-down: the silhouette is a disc about the projected centre.
            self._half = int(math.ceil(self.radius_px)) + 2
            return FrameTruth(t=t, uv=uvc.copy(), xy=xy, uvc=uvc)
        # The silhouette's area centroid, area-weighted over the exposure's
        # nodes (the blurred image is their coverages' mean), in chunks.
        flat = xy_nodes
        cen = np.empty((len(flat), 2))
        area = np.empty(len(flat))
        ext = 0.0
        for a in range(0, len(flat), 4096):
            poly = self.outlines(flat[a:a + 4096])
            q = np.roll(poly, -1, axis=1)
            cr = poly[..., 0] * q[..., 1] - q[..., 0] * poly[..., 1]
            A = cr.sum(axis=1) / 2.0
            cen[a:a + 4096, 0] = ((poly[..., 0] + q[..., 0]) * cr).sum(axis=1) / (6.0 * A)
            cen[a:a + 4096, 1] = ((poly[..., 1] + q[..., 1]) * cr).sum(axis=1) / (6.0 * A)
            area[a:a + 4096] = np.abs(A)
            ok = np.isfinite(poly).all(axis=(1, 2))
            if ok.any():
                ext = max(ext, float(np.ptp(poly[ok], axis=1).max()))
        self._half = int(math.ceil(ext / 2)) + 2
        A = area.reshape(nodes.shape)
        uv = (cen.reshape(nodes.shape + (2,)) * A[..., None]).sum(axis=1) / A.sum(axis=1)[:, None]
        return FrameTruth(t=t, uv=uv, xy=xy, uvc=uvc)

    def ball_patch(self, k: int):
        """Exact blurred coverage of frame ``k`` near the ball.

        Returns ``(cov, u0, v0)``: the coverage patch (0-1) and the pixel
        column and row of its top-left corner, clipped to the frame; ``cov``
        is None when the ball is wholly outside the frame.
        """
        uv = self._uv_nodes[k]
        r = self._half - 1
        umin = max(int(math.floor(uv[:, 0].min() - r - 1)), 0)
        vmin = max(int(math.floor(uv[:, 1].min() - r - 1)), 0)
        umax = min(int(math.ceil(uv[:, 0].max() + r + 1)), self.cam.width - 1)
        vmax = min(int(math.ceil(uv[:, 1].max() + r + 1)), self.cam.height - 1)
        if umax < umin or vmax < vmin:
            return None, 0, 0
        w, h = umax - umin + 1, vmax - vmin + 1
        cov = np.zeros((h, w))
        if self.similar:
            for cu, cv in uv:
                cov += disc_coverage(cu, cv, self.radius_px, umin, vmin, w, h)
        else:
            for xy in self._xy_nodes[k]:
                cov += polygon_coverage_batch(self.outlines(xy), np.array([umin]),
                                              np.array([vmin]), w, h)[0]
        cov /= len(uv)
        return cov, umin, vmin

    # --- realistic look ----------------------------------------------------

    def _init_realistic(self):
        s = self.settings
        cam = self.cam
        h, w = cam.height, cam.width
        self._psf = float(s["psf_sigma"])
        self._pad = int(math.ceil(4 * self._psf)) + 1 if self._psf > 0 else 0
        self._border = 2 * self._half + self._pad + 4
        self._rays = self._ray_map() if cam.is_pinhole else None
        self._struck = {}
        if self.scene.render.get("contacts") and s["balls"]:
            # Balls the shot strikes move after the contact: their own paths,
            # at the tracked ball's exposure nodes.
            from cuespin.physics.contact import scene_trajectory
            for other, path in scene_trajectory(self.scene).struck:
                xy = path.positions(self._t_nodes.ravel()).reshape(self._t_nodes.shape + (2,))
                uv = cam.to_pixels(xy.reshape(-1, 2)).reshape(xy.shape)
                albedo = np.asarray(s["balls"][other].get("colour", [228, 232, 235]), float)
                self._struck[other] = (xy, uv, albedo)
        self._albedo = np.asarray(s["ball_colour"], dtype=np.float64)
        self._mark_colour = np.asarray(s["mark_colour"], dtype=np.float64)
        self._ramp = lk.ramp_image(h, w, float(s["ramp"]), float(s["ramp_angle"]))
        sharp = self._static_scene()
        B = self._border
        # Padded by B on every side, so every ball window near the frame is in range.
        self._sharp = cv2_copy_border(sharp, B)
        blur = gaussian(sharp, self._psf)
        self._blur = blur
        import cv2
        # OpenCV's saturating conversion: np.rint (half to even), then clip to 0-255.
        self.background = cv2.addWeighted(blur, 1.0, blur, 0.0, 0.0, dtype=cv2.CV_8U)
        self._frac = np.subtract(blur, self.background, dtype=np.float32)   # what 8 bits rounded off
        self._frac_tiles = tile_view(self._frac, TILE_PX)
        self._tiles_hw = self._frac_tiles.shape[:2]      # the tiles wholly inside the frame
        self._noise = sensor_noise(self.sigma)
        # The background in int16 only for the noise drawn as integers (large sigma).
        self._bg16 = self.background.astype(np.int16) if isinstance(self._noise, NoiseSampler) else None
        self._orient = None
        if s["markings"] != "none":
            t0 = min(0.0, float(self._t_nodes.min()))
            self._orient = lk.Orientation(lambda t: self.motion(t).w, t0, float(self._t_nodes.max()))
        self._rot_block = (0, np.empty((0,)))
        self._win_block = (0, [])
        self._last_delta = None
        self._stack = None      # the last frame's cue, ball, tiles and their stack

    def _ray_map(self) -> np.ndarray:
        """Unit directions (table frame) of the rays through every pixel of the
        frame padded by ``_border``, float32 (h + 2B, w + 2B, 3); NaN past the
        lens's fold.  Pixel (row i, column j) of the frame is ``[i + B, j + B]``.

        The lens is inverted exactly on a grid every ``RAY_GRID_PX`` pixels and
        interpolated bilinearly between (the rays are smooth: under 0.01 px of
        error at |k1| = 0.25); they serve shading and the cloth, not the
        ball's coverage.
        """
        import cv2

        cam, B, g = self.cam, self._border, RAY_GRID_PX
        H, W = cam.height + 2 * B, cam.width + 2 * B
        gv = np.arange(0, H + g, g, dtype=np.float64)
        gu = np.arange(0, W + g, g, dtype=np.float64)
        uu, vv = np.meshgrid(gu - B, gv - B)
        n = cam._from_px(np.column_stack([uu.ravel(), vv.ravel()]))   # undistorted, normalised
        d = np.column_stack([n, np.ones(len(n))]) @ cam.rotation        # R^T (x, y, 1)
        d = d.reshape(uu.shape + (3,)).astype(np.float32)
        mu, mv = np.meshgrid(np.arange(W, dtype=np.float32) / g, np.arange(H, dtype=np.float32) / g)
        full = cv2.remap(d, mu, mv, cv2.INTER_LINEAR)
        full /= np.linalg.norm(full, axis=-1, keepdims=True)
        return full

    def _plane_points(self, v0: int, v1: int, u0: int, u1: int, z: float) -> np.ndarray:
        """Table points (m) at height ``z`` seen at frame pixels ``[v0:v1, u0:u1]``
        (pose cameras); far away where the ray never meets the plane."""
        B = self._border
        d = self._rays[v0 + B:v1 + B, u0 + B:u1 + B].astype(np.float64)
        C = self.cam.centre
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z - C[2]) / d[..., 2]
            xy = C[:2] + s[..., None] * d[..., :2]
        bad = ~(s > 0) | ~np.isfinite(xy).all(-1)
        xy[bad] = 1e3
        return xy

    def _cloth_points(self, uv: np.ndarray) -> np.ndarray:
        """Table points (m) on the cloth seen at pixels ``uv`` (..., 2)."""
        if self.cam.has_lens:
            return self.cam.to_table(uv.reshape(-1, 2)).reshape(uv.shape)
        # Elementwise (a matmul with an inner size of 2 is slow on large arrays).
        Hi = np.linalg.inv(self.H)
        u, v = uv[..., 0], uv[..., 1]
        den = Hi[2, 0] * u + Hi[2, 1] * v + Hi[2, 2]
        return np.stack([(Hi[0, 0] * u + Hi[0, 1] * v + Hi[0, 2]) / den,
                         (Hi[1, 0] * u + Hi[1, 1] * v + Hi[1, 2]) / den], -1)

    def _cloth_grid(self, h: int, w: int) -> np.ndarray:
        """:meth:`_cloth_points` of every pixel of an ``h x w`` frame, (h, w, 2)."""
        if self.cam.has_lens:
            vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
            return self._cloth_points(np.stack([uu, vv], -1))
        # The same elementwise homography, its pixel coordinates broadcast
        # (a row of u, a column of v) rather than two full grids.
        Hi = np.linalg.inv(self.H)
        u = np.arange(w, dtype=np.float64)[None, :]
        v = np.arange(h, dtype=np.float64)[:, None]
        den = Hi[2, 0] * u + Hi[2, 1] * v + Hi[2, 2]
        return np.stack([(Hi[0, 0] * u + Hi[0, 1] * v + Hi[0, 2]) / den,
                         (Hi[1, 0] * u + Hi[1, 1] * v + Hi[1, 2]) / den], -1)

    def _homography_labels(self, h: int, w: int):
        """The table parts' labels (:func:`~cuespin.render.look.table_labels`)
        at every pixel of an ``h x w`` frame through a homography, and the
        cloth point of any pixels, ``at(rows, cols) -> (x, y)`` (m).

        :meth:`_cloth_grid`'s arithmetic, but only where a part other than the
        cloth may be: a tile whose corners all lie farther inside every edge
        than the largest pocket's radius (the pockets' centres lie on or
        outside the cushion line) is cloth at every pixel (the homography maps
        the tile onto the convex hull of its corners' points, the denominator
        keeping its sign there); one wholly past the rails' outer edge (and
        every pocket's reach) on one side is beyond at every pixel.  The
        table's parts are computed on the other tiles only (a fifth to a
        third of a framed view's pixels).
        """
        Hi = np.linalg.inv(self.H)

        def at(rows, cols):
            u, v = cols.astype(np.float64), rows.astype(np.float64)
            den = Hi[2, 0] * u + Hi[2, 1] * v + Hi[2, 2]
            return ((Hi[0, 0] * u + Hi[0, 1] * v + Hi[0, 2]) / den,
                    (Hi[1, 0] * u + Hi[1, 1] * v + Hi[1, 2]) / den)

        tb, T = self.scene.table, LABEL_TILE_PX
        L, W = tb.length, tb.width
        pk = lk.pockets(L, W)
        # 1 mm to spare: rounding is ~1e-16 m.
        m = max(r for _, _, r in pk) + 1e-3
        # Beyond the rails: past every pocket's reach outside the cushion line too.
        e = max([lk.CUSHION_WIDTH_M + lk.RAIL_WIDTH_M]
                + [max(-px, px - L, -py, py - W, 0.0) + r for px, py, r in pk]) + 1e-3
        r0 = np.arange(0, h, T)
        c0 = np.arange(0, w, T)
        rows = np.stack([r0, np.minimum(r0 + T - 1, h - 1)])[:, :, None, None]   # (2, th, 1, 1)
        cols = np.stack([c0, np.minimum(c0 + T - 1, w - 1)], -1)[None, None]    # (1, 1, tw, 2)
        rows, cols = np.broadcast_arrays(rows, cols)                             # (2, th, tw, 2)
        x, y = at(rows, cols)
        den = Hi[2, 0] * cols + Hi[2, 1] * rows + Hi[2, 2]

        def every(c):                                      # at all four corners of a tile
            return c.all(axis=(0, 3))

        convex = every(den > 0) | every(den < 0)
        inner = convex & every((x >= m) & (x <= L - m) & (y >= m) & (y <= W - m))
        # Wholly in one half-plane past the rails' outer edge.
        beyond = convex & (every(x <= -e) | every(x >= L + e) | every(y <= -e) | every(y >= W + e))
        code = np.full(inner.shape, 255, np.uint8)
        code[inner] = lk.TABLE_PARTS.index("cloth")
        code[beyond] = lk.TABLE_PARTS.index("beyond")
        label = np.ascontiguousarray(np.repeat(np.repeat(code, T, axis=0), T, axis=1)[:h, :w])
        ti, tj = np.nonzero(code == 255)
        a = np.arange(T)
        rr = np.broadcast_to(ti[:, None, None] * T + a[:, None], (len(ti), T, T))
        cc = np.broadcast_to(tj[:, None, None] * T + a[None, :], (len(tj), T, T))
        keep = (rr < h) & (cc < w)
        rr, cc = rr[keep], cc[keep]
        label[rr, cc] = lk.table_labels(*at(rr, cc), L, W)
        return label, at

    def _static_scene(self) -> np.ndarray:
        """The static scene before lens blur, float32 (h, w, 3): cloth with its
        texture, cushions, rails, pockets and sights (2x2 supersampled),
        under the lighting ramp, and the other balls at rest."""
        s, cam, tb = self.settings, self.cam, self.scene.table
        h, w = cam.height, cam.width
        felt = np.asarray(s["felt_colour"], dtype=np.float32)
        # Colours of lk.TABLE_PARTS, in its order.
        palette = np.array([felt, 0.8 * felt, s["rail_colour"], [215, 228, 235], [16, 16, 18],
                            [35, 35, 38]], np.float32)
        if s["rails"]:
            tb_lw = (tb.length, tb.width)
            if cam.is_pinhole or cam.has_lens:
                xy = self._plane_points(0, h, 0, w, 0.0) if cam.is_pinhole else self._cloth_grid(h, w)
                label = lk.table_labels(xy[..., 0], xy[..., 1], *tb_lw)

                def at(rows, cols):
                    return xy[rows, cols, 0], xy[rows, cols, 1]
            else:
                label, at = self._homography_labels(h, w)
            # Labels at pixel centres; pixels on an edge between parts (a
            # neighbour differs) are supersampled 4 x 4 from the local map's
            # derivatives, the rest take their one label.
            import cv2
            kernel = np.ones((3, 3), np.uint8)
            edge = cv2.dilate(label, kernel) != cv2.erode(label, kernel)
            img = lookup_colours(palette, label)
            felt_share = (label <= 1).astype(np.float32)
            ev, eu = np.nonzero(edge)
            if len(ev):
                ss = 4
                off = (np.arange(ss) + 0.5) / ss - 0.5
                ou, ov = np.meshgrid(off, off)
                ou, ov = ou.ravel()[None, :], ov.ravel()[None, :]
                dx_du, dy_du = gradient_at(at, ev, eu, 1, w)
                dx_dv, dy_dv = gradient_at(at, ev, eu, 0, h)
                x, y = at(ev, eu)
                sub = lk.table_labels(x[:, None] + ou * dx_du[:, None] + ov * dx_dv[:, None],
                                      y[:, None] + ou * dy_du[:, None] + ov * dy_dv[:, None],
                                      *tb_lw)                       # (n_edge, 16)
                img[ev, eu] = lookup_colours(palette, sub).mean(axis=1)
                felt_share[ev, eu] = (sub <= 1).mean(axis=1)
        else:
            img = np.empty((h, w, 3), np.float32)
            img[:] = felt
            felt_share = np.ones((h, w), np.float32)
        tex_amp = float(s["texture"])
        if tex_amp > 0:
            rng = np.random.default_rng(np.random.SeedSequence([int(s["seed"]), 7]))
            tex = lk.felt_texture((h, w), float(s["texture_scale"]), rng)
            img *= (1.0 + tex_amp * tex * felt_share)[..., None]
        img *= self._ramp[..., None]
        # Other balls at rest, lit like the tracked one, drawn with exact
        # coverage; a ball the shot strikes (render.contacts) is drawn per frame.
        for i, b in enumerate(s["balls"]):
            if i in self._struck:
                continue
            xy = np.array([[float(b["x"]), float(b["y"])]])
            albedo = np.asarray(b.get("colour", [228, 232, 235]), dtype=np.float64)
            self._composite_ball(img, cam.to_pixels(xy), xy, albedo, None, 0)
        return img

    def _ball_windows(self, uv: np.ndarray, xy: np.ndarray, albedo: np.ndarray, rots):
        """Colour and coverage of the ball at nodes with centres ``xy`` (K, 2) (m),
        imaged at ``uv`` (K, 2) (px).

        Returns ``(cov (K, n, n), colour (K, n, n, 3), iu (K,), iv (K,))``:
        each node's exact coverage and shaded colour on its own window whose
        top-left pixel is ``(iu, iv)``.  The colour is evaluated at pixel
        centres (normals clamped to the rim), the coverage is exact, so the
        silhouette's centroid stays exact.  Through a pose camera the normal
        is where each pixel's ray meets the sphere (or, past the rim, the
        sphere's point nearest the ray) and the highlight follows the ray.
        """
        half, r, R = self._half, self.radius_px, self.scene.physics.R
        n = 2 * half + 1
        a = np.arange(n)
        view = None
        if self.similar:
            iu = np.floor(uv[:, 0]).astype(int) - half
            iv = np.floor(uv[:, 1]).astype(int) - half
            cov = disc_coverage_batch(uv[:, 0], uv[:, 1], r, iu, iv, n)
        else:
            poly = self.outlines(xy)
            mid = 0.5 * (poly.min(axis=1) + poly.max(axis=1))
            iu = np.floor(mid[:, 0]).astype(int) - half
            iv = np.floor(mid[:, 1]).astype(int) - half
            cov = polygon_coverage_batch(poly, iu, iv, n, n)
        if self.cam.is_pinhole:
            B = self._border
            rows = (iv[:, None] + a + B)[:, :, None]
            cols = (iu[:, None] + a + B)[:, None, :]
            d = self._rays[np.clip(rows, 0, self._rays.shape[0] - 1),
                           np.clip(cols, 0, self._rays.shape[1] - 1)].astype(np.float64)
            C = self.cam.centre
            P = np.c_[xy, np.full(len(xy), R)][:, None, None, :]
            ts = np.einsum("kabi,kabi->kab", P - C, d)
            D = C + ts[..., None] * d - P                     # centre to the ray's nearest point
            dist2 = np.einsum("kabi,kabi->kab", D, D)
            hit = dist2 <= R * R
            back = np.sqrt(np.maximum(R * R - dist2, 0.0))
            normals = np.where(hit[..., None], (D - back[..., None] * d) / R,
                               D / np.sqrt(np.maximum(dist2, 1e-300))[..., None])
            normals = np.nan_to_num(normals)
            view = -d
        else:
            du = (iu[:, None] + a - uv[:, 0:1])[:, None, :] * np.ones((1, n, 1))
            dv = (iv[:, None] + a - uv[:, 1:2])[:, :, None] * np.ones((1, 1, n))
            # px -> ball radii: the local inverse Jacobian (a similarity's, or
            # any other homography's at each node: an orthographic view).
            Ji = (self._Jinv if self.similar else np.linalg.inv(self.cam.jacobian(xy))) / R
            Ji = np.broadcast_to(Ji, (len(uv), 2, 2))[:, :, :, None, None]
            nx = Ji[:, 0, 0] * du + Ji[:, 0, 1] * dv
            ny = Ji[:, 1, 0] * du + Ji[:, 1, 1] * dv
            rho2 = nx * nx + ny * ny
            shrink = np.where(rho2 > 1.0, 1.0 / np.sqrt(np.maximum(rho2, 1e-300)), 1.0)
            nx, ny = nx * shrink, ny * shrink
            nz = np.sqrt(np.maximum(1.0 - nx * nx - ny * ny, 0.0))
            normals = np.stack([nx, ny, nz], -1)
        alb = np.broadcast_to(albedo, normals.shape)
        if rots is not None and self.settings["markings"] != "none":
            # R^T n: table -> body; einsum's sums (j in order) written out, the
            # same values at a quarter of its cost.
            R = rots[:, None, None]
            n0, n1, n2 = normals[..., 0], normals[..., 1], normals[..., 2]
            body = np.stack([R[..., 0, i] * n0 + R[..., 1, i] * n1 + R[..., 2, i] * n2 for i in range(3)], -1)
            m = lk.mark_mask(body, self.settings["markings"], r)[..., None]
            alb = alb * (1.0 - m) + self._mark_colour * m
        colour = lk.shade(normals, alb, self.settings, view)
        return cov, colour, iu, iv

    def _composite_ball(self, img, uv, xy, albedo, rots, pad):
        """Draw a ball averaged over nodes at ``xy`` (K, 2) (m), imaged at ``uv``
        (K, 2) (px), into the sharp image ``img``."""
        cov, colour, iu, iv = self._ball_windows(uv, xy, albedo, rots)
        h, w = img.shape[:2]
        n = cov.shape[1]
        K = len(uv)
        ramp = self._ramp
        # Each node's ramp pixel, clipped to the frame (one call, not 2K scalar clips).
        ru = np.clip(uv[:, 0], 0, ramp.shape[1] - 1).astype(int)
        rv = np.clip(uv[:, 1], 0, ramp.shape[0] - 1).astype(int)
        for i in range(K):
            u0, v0 = iu[i] + pad, iv[i] + pad
            if u0 + n <= 0 or v0 + n <= 0 or u0 >= w or v0 >= h:
                continue
            cu, cv = ru[i], rv[i]
            a0, b0 = max(u0, 0), max(v0, 0)
            a1, b1 = min(u0 + n, w), min(v0 + n, h)
            sl = (slice(b0 - v0, b1 - v0), slice(a0 - u0, a1 - u0))
            c = cov[i][sl][..., None] / K
            img[b0:b1, a0:a1] += c * (colour[i][sl] * ramp[cv, cu] - img[b0:b1, a0:a1])
        return img

    def _ball_delta(self, k: int):
        """The ball's change to the blurred background near it in frame ``k``.

        Returns ``(delta (h, w, 3) float32, u0, v0)`` in frame pixels, or
        ``(None, 0, 0)`` when the ball is out of view.
        """
        rots = self._rotations(k)
        # A ball at rest (before the strike, after it stops) looks the same
        # in every frame: its last change is reused while nodes and turn agree.
        key = self._uv_nodes[k].tobytes() + (b"" if rots is None else rots.tobytes())
        if self._last_delta is not None and self._last_delta[0] == key:
            return self._last_delta[1]
        win = self._windows(k)
        if win is None:
            out = None, 0, 0
        else:
            out = self._accumulate(*win, self._uv_nodes.shape[1])
        self._last_delta = (key, out)
        return out

    def _visible(self, uv: np.ndarray) -> np.ndarray:
        """Which nodes imaged at ``uv`` (K, 2) px have their window in the frame."""
        half, h, w = self._half, self.cam.height, self.cam.width
        return ((uv[:, 0] + half >= 0) & (uv[:, 0] - half <= w - 1)
                & (uv[:, 1] + half >= 0) & (uv[:, 1] - half <= h - 1))

    def _windows(self, k: int):
        """The tracked ball's :meth:`_ball_windows` at frame ``k``'s visible nodes,
        ``(uv, cov, colour, iu, iv)`` (None out of view), computed for a block
        of frames in one vectorised call: a frame's few nodes spent most of
        their time in numpy's per-call overhead.  Each pixel's arithmetic is
        the same whatever the batch."""
        start, block = self._win_block
        if not start <= k < start + len(block):
            K = self._uv_nodes.shape[1]
            frames = range(k, min(k + max(1, WINDOW_BLOCK_NODES // K), self.n_frames))
            parts = []
            for f in frames:
                uv = self._uv_nodes[f]
                vis = self._visible(uv)
                rots = self._rotations(f)
                parts.append((uv[vis], self._xy_nodes[f][vis], None if rots is None else rots[vis]))
            counts = [len(p[0]) for p in parts]
            block = [None] * len(parts)
            if sum(counts):
                uv = np.concatenate([p[0] for p in parts])
                rots = None if self._orient is None else np.concatenate([p[2] for p in parts])
                cov, colour, iu, iv = self._ball_windows(uv, np.concatenate([p[1] for p in parts]),
                                                         self._albedo, rots)
                ends = np.cumsum(counts)
                for j, (c, e) in enumerate(zip(counts, ends)):
                    if c:
                        sl = slice(e - c, e)
                        block[j] = (uv[sl], cov[sl], colour[sl], iu[sl], iv[sl])
            self._win_block = start, block = k, block
        return block[k - start]

    def _rotations(self, k: int):
        """Body-to-table rotations (K, 3, 3) of the tracked ball at frame ``k``'s
        nodes (None without markings), evaluated for blocks of frames in one
        vectorised call (per frame, the call's overhead was a third of the ball's cost)."""
        if self._orient is None:
            return None
        start, block = self._rot_block
        if not start <= k < start + len(block):
            K = self._t_nodes.shape[1]
            n = max(1, ROTATION_BLOCK_NODES // K)
            block = self._orient(self._t_nodes[k:k + n])
            self._rot_block = start, block = k, block
        return block[k - start]

    def _delta_of(self, uv, xy, albedo, rots):
        """:meth:`_ball_delta` for any ball: nodes imaged at ``uv`` (K, 2) px,
        centred at ``xy`` (K, 2) m, its albedo and the nodes' rotations (K, 3, 3)
        (None: no markings)."""
        K = len(uv)
        vis = self._visible(uv)
        if not vis.any():
            return None, 0, 0
        uv = uv[vis]
        rots = rots[vis] if rots is not None else None
        return self._accumulate(uv, *self._ball_windows(uv, xy[vis], albedo, rots), K)

    def _accumulate(self, uv, cov, colour, iu, iv, K: int):
        """The blurred change of a ball's windows (:meth:`_ball_windows` at its
        visible nodes ``uv``) averaged over all ``K`` nodes, cropped to the frame."""
        B, pad = self._border, self._pad
        h, w = self.cam.height, self.cam.width
        n = cov.shape[1]
        pu0, pv0 = int(iu.min()) - pad, int(iv.min()) - pad       # frame coords of the patch
        pw, ph = int(iu.max()) + n + pad - pu0, int(iv.max()) + n + pad - pv0
        sharp = self._sharp[pv0 + B:pv0 + B + ph, pu0 + B:pu0 + B + pw]
        delta = np.zeros((ph, pw, 3), np.float32)
        ramp = self._ramp
        ru = np.clip(uv[:, 0], 0, w - 1).astype(int)
        rv = np.clip(uv[:, 1], 0, h - 1).astype(int)
        for i in range(len(uv)):
            a, b = iu[i] - pu0, iv[i] - pv0
            cu, cv = ru[i], rv[i]
            delta[b:b + n, a:a + n] += (cov[i][..., None] / K) * (
                colour[i] * ramp[cv, cu] - sharp[b:b + n, a:a + n])
        delta = gaussian(delta, self._psf, constant=True)
        # Crop to the frame.
        a0, b0 = max(pu0, 0), max(pv0, 0)
        a1, b1 = min(pu0 + pw, w), min(pv0 + ph, h)
        if a1 <= a0 or b1 <= b0:
            return None, 0, 0
        return delta[b0 - pv0:b1 - pv0, a0 - pu0:a1 - pu0], a0, b0

    def cue_tip(self, t: np.ndarray) -> np.ndarray:
        """Distance (m) of the cue's tip behind the ball's rest contact point at times ``t``.

        At address ``cue_gap`` behind the ball; it approaches at the cue's
        speed (half the ball's, at least 0.3 m/s) to touch the ball at
        ``t0``, follows through ``cue_follow`` past the contact point (never
        into the departing ball), then withdraws at 1 m/s to 0.15 m behind
        the contact point and is held there.  Negative is past the contact point.
        """
        s, tr = self.settings, self.scene.truth
        t = np.asarray(t, dtype=float)
        v0 = np.asarray(tr.v0)
        speed = float(np.hypot(*v0))
        vc = max(0.5 * speed, 0.3)
        g0, f = float(s["cue_gap"]), max(float(s["cue_follow"]), 1e-6)
        tf = 3.0 * f / vc                              # follow-through time (s)
        gap = np.where(t < tr.t0, np.minimum(g0, vc * (tr.t0 - t)),
                       -f * (1.0 - np.exp(-(t - tr.t0) * vc / f)))
        back = t > tr.t0 + tf
        gap = np.where(back, np.minimum(-f * (1 - math.exp(-3.0)) + 1.0 * (t - tr.t0 - tf), 0.15),
                       gap)
        # The tip stays behind the ball's rear point.
        d_hat = v0 / max(speed, 1e-12)
        moved = (self.motion(t).x - np.asarray(tr.x0)) @ d_hat
        return np.maximum(gap, -moved)

    def _cue_tiles(self, k: int) -> dict:
        """The cue's change to the blurred background in frame ``k``, as tiles
        (:func:`add_to_tiles`): one patch per stretch of the cue (each pixel
        belongs to one stretch, so overlapping patches add exactly)."""
        if not self.settings["cue"]:
            return _NO_TILES
        tr = self.scene.truth
        v0 = np.asarray(tr.v0)
        speed = float(np.hypot(*v0))
        if speed <= 0:
            return _NO_TILES
        d = v0 / speed
        nrm = np.array([-d[1], d[0]])
        R = self.scene.physics.R
        # The cue's state at the frame's middle (its own blur is not drawn);
        # a cue held still is drawn once.
        if getattr(self, "_cue_gaps", None) is None:   # every frame's in one vectorised call
            self._cue_gaps = self.cue_tip(self.truth.t)
        gap = float(self._cue_gaps[k])
        cached = getattr(self, "_cue_cache", None)
        if cached is not None and cached[0] == gap:
            return cached[1]
        tip = np.asarray(tr.x0) - d * (R + gap)
        px_m = self.radius_px / R
        h, w = self.cam.height, self.cam.width
        tiles: dict = {}
        step = 48.0 / px_m                      # a stretch of about 48 px
        edges = np.arange(0.0, CUE_LENGTH_M + step, step)
        edges[-1] = CUE_LENGTH_M
        pad = self._pad + 2
        # Every stretch's four corners in one projection (the cue's axis at
        # the ball's centre height).
        a_c = np.repeat(np.c_[edges[:-1], edges[1:]], 2, axis=1)              # (m, 4)
        c_c = np.array([-1.0, 1.0, -1.0, 1.0]) * cue_radius(edges[1:])[:, None]
        xy_c = tip - a_c[..., None] * d + c_c[..., None] * nrm                 # (m, 4, 2)
        uv_all = self.cam.project(np.c_[xy_c.reshape(-1, 2), np.full(xy_c.size // 2, R)])
        uv_all = uv_all.reshape(-1, 4, 2)
        # Every stretch's patch in the frame at once (most of a long cue is
        # often out of view: per stretch, these reductions cost as much as a drawn one).
        seen = np.isfinite(uv_all).all(axis=(1, 2))
        lo = np.floor(np.where(seen[:, None], uv_all.min(axis=1), 0.0)).astype(int) - pad
        hi = np.ceil(np.where(seen[:, None], uv_all.max(axis=1), -1.0)).astype(int) + pad
        lo, hi = np.maximum(lo, 0), np.minimum(hi, [w - 1, h - 1])
        seen &= (hi >= lo).all(axis=1)
        for i in np.flatnonzero(seen):
            a0, a1 = edges[i], edges[i + 1]
            (u_lo, v_lo), (u_hi, v_hi) = lo[i].tolist(), hi[i].tolist()
            shape = (v_hi + 1 - v_lo, u_hi + 1 - u_lo)
            if self.similar:
                # Affine in the pixel's position: two 1-D ramps, no per-pixel mapping.
                rel0 = self.cam.to_table(np.array([[u_lo, v_lo]], float))[0] - tip
                ju, jv = self._Jinv[:, 0], self._Jinv[:, 1]
                du = np.arange(shape[1], dtype=np.float64)[None, :]
                dv = np.arange(shape[0], dtype=np.float64)[:, None]
                a = -(rel0 @ d) - (ju @ d) * du - (jv @ d) * dv     # along the cue from its tip (m)
                c = (rel0 @ nrm) + (ju @ nrm) * du + (jv @ nrm) * dv  # across (m)
            else:
                if self.cam.is_pinhole:
                    xy = self._plane_points(v_lo, v_hi + 1, u_lo, u_hi + 1, R)
                else:
                    vv, uu = np.mgrid[v_lo:v_hi + 1, u_lo:u_hi + 1]
                    xy = self._cloth_points(np.stack([uu, vv], -1).astype(float))
                rel = xy - tip
                a = -(rel @ d)
                c = rel @ nrm
            own = (a >= a0) & (a < a1) if a0 > 0 else (a < a1)
            # np.minimum / np.maximum: np.clip's values without its call overhead.
            ra = cue_radius(np.minimum(np.maximum(a, 0.0), CUE_LENGTH_M))
            cov = (np.minimum(np.maximum((ra - np.abs(c)) * px_m + 0.5, 0.0), 1.0)
                   * np.minimum(np.maximum(a * px_m + 0.5, 0.0), 1.0) * own)
            on = cov > 0
            if not on.any():
                continue
            # Colour only where the cue is (it is thin): its part, cylinder shading.
            a_on, c_on, ra_on = a[on], c[on], ra[on]
            across = np.minimum(np.maximum(np.abs(c_on) / ra_on, 0.0), 1.0)
            colour = cue_colour(a_on) * (0.55 + 0.45 * np.sqrt(1 - across**2))[:, None]
            sharp = self._sharp[v_lo + self._border:v_hi + 1 + self._border,
                                u_lo + self._border:u_hi + 1 + self._border]
            ramp = self._ramp[v_lo:v_hi + 1, u_lo:u_hi + 1]
            delta = np.zeros(shape + (3,), np.float32)
            delta[on] = cov[on][:, None] * (colour * ramp[on][:, None] - sharp[on])
            add_to_tiles(tiles, gaussian(delta, self._psf, constant=True), u_lo, v_lo)
        self._cue_cache = (gap, tiles)
        return tiles

    def _render_realistic(self, k: int, rng: np.random.Generator) -> np.ndarray:
        import cv2

        if self.sigma > 0:
            if not isinstance(self._noise, NoiseSampler):
                frame = self._noise.add_to(self.background, rng)    # one word of rng seeds the frame
            else:
                # SFC64 writes random bytes about a third faster than PCG64; seeded
                # from the caller's generator, so frames stay reproducible.
                fast = np.random.Generator(np.random.SFC64(int(rng.integers(0, 2**63))))
                frame = cv2.add(self._noise.draw(fast, self._bg16.shape), self._bg16, dtype=cv2.CV_8U)
        else:
            frame = self.background.copy()
        cue, ball = self._cue_tiles(k), self._ball_delta(k)
        last = self._stack
        if not self._struck and last is not None and last[0] is cue and last[1] is ball:
            # Cue and ball as in the last frame (both drawn once while
            # still): its tiles and their stack again, not rebuilt.
            tiles, full, ty, tx, acc = last[2:]
        else:
            tiles = dict(cue)
            for xy, uv, albedo in self._struck.values():
                delta, u0, v0 = self._delta_of(uv[k], xy[k], albedo, None)
                if delta is not None:
                    add_to_tiles(tiles, delta, u0, v0)
            delta, u0, v0 = ball
            if delta is not None:
                add_to_tiles(tiles, delta, u0, v0)
            full = [(key, acc) for key, acc in tiles.items()
                    if key[0] < self._tiles_hw[0] and key[1] < self._tiles_hw[1]]
            ty = np.array([key[0] for key, _ in full], dtype=np.intp)
            tx = np.array([key[1] for key, _ in full], dtype=np.intp)
            acc = np.concatenate([a for _, a in full]) if full else None
            self._stack = (cue, ball, tiles, full, ty, tx, acc)
        # The frame is round(blur + n) with integer noise n: adding the
        # change to the unrounded value keeps it round(blur + delta + n).
        # OpenCV's float32 sums in numpy's order ((f + frac) + acc) and its
        # saturating conversion (round half to even, as np.rint, then clip):
        # the same pixels as numpy's five passes.  The tiles wholly inside
        # the frame are gathered into one stack and added in two calls (two
        # calls a tile cost ~0.4 ms a frame in calls alone); the frame's
        # partial edge tiles one by one, the same arithmetic.
        T = TILE_PX
        if full:
            view = tile_view(frame, T)
            clean = cv2.add(view[ty, tx].reshape(-1, T, 3), self._frac_tiles[ty, tx].reshape(-1, T, 3),
                            dtype=cv2.CV_32F)
            view[ty, tx] = cv2.add(clean, acc, dtype=cv2.CV_8U).reshape(-1, T, T, 3)
        if len(full) < len(tiles):
            for (ty, tx), acc in tiles.items():
                if ty < self._tiles_hw[0] and tx < self._tiles_hw[1]:
                    continue
                sl = (slice(ty * T, ty * T + T), slice(tx * T, tx * T + T))
                f = frame[sl]
                clean = cv2.add(f, self._frac[sl], dtype=cv2.CV_32F)
                frame[sl] = cv2.add(clean, acc[:f.shape[0], :f.shape[1]], dtype=cv2.CV_8U)
        return frame

    def render(self, k: int, rng: np.random.Generator) -> np.ndarray:
        """Frame ``k`` as an 8-bit image: grey (height, width) in the plain
        look, BGR (height, width, 3) in the realistic one.

        Parameters
        ----------
        k : int
            Frame index.
        rng : numpy.random.Generator
            Noise source; frames drawn in order from one generator are
            independent.
        """
        if self.realistic:
            return self._render_realistic(k, rng)
        bg = self.background
        if self._plain_noise is not None:
            frame = self._plain_noise.add_to(bg, rng)     # the law of self.lut, exactly
        elif self.sigma > 0:
            u = np.frombuffer(rng.bytes(2 * bg.size), dtype=np.uint16).reshape(bg.shape)
            frame = np.take(self.lut, u)
            frame += bg
            np.clip(frame, 0, 255, out=frame)
            frame = frame.astype(np.uint8)
        else:
            frame = bg.copy()
        cov, u0, v0 = self.ball_patch(k)
        if cov is not None:
            h, w = cov.shape
            felt = bg[v0:v0 + h, u0:u0 + w].astype(np.float64)
            clean = felt + (self.ball - felt) * cov
            if self.sigma > 0:
                clean += self.sigma * rng.standard_normal(clean.shape)
            frame[v0:v0 + h, u0:u0 + w] = np.clip(np.rint(clean), 0, 255).astype(np.uint8)
        return frame

    def frames(self, seed=None):
        """Yield every frame in order, drawn from one local generator."""
        if seed is None:
            seed = int(self.settings["seed"])
        rng = np.random.default_rng(seed)
        for k in range(self.n_frames):
            yield self.render(k, rng)


# The cue (m): length, tip and butt radii, and where its parts end from the tip.
CUE_LENGTH_M = 1.45
CUE_TIP_R_M, CUE_BUTT_R_M = 0.0065, 0.0145
CUE_PARTS = ((0.008, (160, 95, 45)),     # chalked tip, blue
             (0.030, (220, 232, 238)),   # ferrule, ivory
             (0.90, (125, 175, 215)),    # maple shaft
             (CUE_LENGTH_M + 1, (35, 45, 70)))   # dark butt


def cue_radius(a):
    """The cue's radius (m) at distance ``a`` (m) from its tip: a linear taper."""
    return CUE_TIP_R_M + (CUE_BUTT_R_M - CUE_TIP_R_M) * np.asarray(a) / CUE_LENGTH_M


def cue_colour(a: np.ndarray) -> np.ndarray:
    """BGR colour of the cue at distances ``a`` (m) from its tip, shape (n, 3)."""
    return _CUE_COLS[np.minimum(np.searchsorted(_CUE_ENDS, a), len(_CUE_ENDS) - 1)]


_CUE_ENDS = np.array([e for e, _ in CUE_PARTS])
_CUE_COLS = np.array([c for _, c in CUE_PARTS], dtype=np.float32)


TILE_PX = 32
# No cue: one shared empty set of tiles (never changed: frames copy it), so a
# frame's stack can be reused while the ball is still.
_NO_TILES: dict = {}


def add_to_tiles(tiles: dict, delta: np.ndarray, u0: int, v0: int) -> dict:
    """Add a patch ``delta`` (h, w, 3) at frame pixel ``(u0, v0)`` into a dict of
    ``TILE_PX`` square tiles keyed by ``(row, column)``; tiles it touches are
    copied first, so a dict shared with a cache is never changed."""
    T = TILE_PX
    h, w = delta.shape[:2]
    for ty in range(v0 // T, (v0 + h - 1) // T + 1):
        for tx in range(u0 // T, (u0 + w - 1) // T + 1):
            a0, a1 = max(tx * T, u0), min(tx * T + T, u0 + w)
            b0, b1 = max(ty * T, v0), min(ty * T + T, v0 + h)
            tile = tiles.get((ty, tx))
            tile = np.zeros((T, T, 3), np.float32) if tile is None else tile.copy()
            tile[b0 - ty * T:b1 - ty * T, a0 - tx * T:a1 - tx * T] += delta[b0 - v0:b1 - v0,
                                                                          a0 - u0:a1 - u0]
            tiles[(ty, tx)] = tile
    return tiles


def lookup_colours(palette: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """``palette[labels]`` for a (n, 3) float32 palette and 2-D uint8 labels:
    OpenCV's table lookup on the labels in three channels, the same values
    at a twentieth of numpy's fancy indexing's cost (12 ms a 1280 x 720 frame)."""
    import cv2

    table = np.zeros((256, 1, 3), np.float32)
    table[:len(palette), 0] = palette
    return cv2.LUT(cv2.merge([labels, labels, labels]), table)


def tile_view(img: np.ndarray, T: int) -> np.ndarray:
    """The ``T x T`` tiles wholly inside a C-contiguous ``img`` (h, w, ...) as a
    writeable view, shape (h // T, w // T, T, T, ...): tile ``(ty, tx)`` is
    ``img[ty T:ty T + T, tx T:tx T + T]``."""
    s0, s1 = img.strides[:2]
    return np.lib.stride_tricks.as_strided(img, (img.shape[0] // T, img.shape[1] // T, T, T) + img.shape[2:],
                                           (T * s0, T * s1, s0, s1) + img.strides[2:])


def gaussian(img: np.ndarray, sigma: float, constant: bool = False) -> np.ndarray:
    """Gaussian blur (the lens's PSF) of a float image; zero outside when ``constant``."""
    import cv2

    img = np.ascontiguousarray(img, dtype=np.float32)
    if sigma <= 0:
        return img
    border = cv2.BORDER_CONSTANT if constant else cv2.BORDER_REFLECT
    return cv2.GaussianBlur(img, (0, 0), sigma, borderType=border)


def gradient_at(at, rows: np.ndarray, cols: np.ndarray, axis: int, n: int) -> tuple:
    """``np.gradient(a, axis=axis)[rows, cols]`` of a map of two coordinates,
    ``at(rows, cols) -> (x, y)``, of ``n`` pixels along ``axis``, computed at
    those pixels only: central differences inside, one-sided at the borders,
    the same arithmetic."""
    idx = cols if axis == 1 else rows
    lo, hi = np.maximum(idx - 1, 0), np.minimum(idx + 1, n - 1)
    (xh, yh), (xl, yl) = (at(rows, hi), at(rows, lo)) if axis == 1 else (at(hi, cols), at(lo, cols))
    inner = (idx > 0) & (idx < n - 1)
    out = []
    for d in (xh - xl, yh - yl):
        d[inner] = d[inner] / 2.0
        out.append(d)
    return tuple(out)


def cv2_copy_border(img: np.ndarray, b: int) -> np.ndarray:
    """``img`` padded by ``b`` pixels on every side, edges replicated."""
    import cv2

    return cv2.copyMakeBorder(img, b, b, b, b, cv2.BORDER_REPLICATE)


def video_length(scene: Scene) -> int:
    """Frames in a scene's video: the ``render.duration`` if set, otherwise
    until the ball stops (plus ``tail``) or its centre leaves the table."""
    s = render_settings(scene)
    fps = scene.camera.fps
    if s["duration"] is not None:
        return max(1, int(round(float(s["duration"]) * fps)))
    end, left = motion_end(scene.truth, scene.physics, scene.table, fps, float(s["max_duration"]))
    if scene.render.get("contacts"):  # bounced back, not gone: until it stops
        end, left = min(scene_trajectory(scene).t_rest, float(s["max_duration"])), False
    if not left:
        end = min(end + float(s["tail"]), float(s["max_duration"]))
    return int(math.floor(end * fps)) + 1
