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

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from cuespin.physics.motion import evaluate, phases
from cuespin.physics.scene import Scene, homography_jacobian, motion_end
from cuespin.render import look as lk
from cuespin.render.timing import frame_times

# Blur nodes are spaced at most this far apart (px) along the path, so the
# blurred streak is smooth; the centroid is exact whatever the spacing.
BLUR_NODE_SPACING_PX = 0.25
MAX_BLUR_NODES = 256
# A homography whose local Jacobian departs from a similarity by more than
# this (relative) would image the ball as an ellipse, which is not modelled.
SIMILARITY_RTOL = 1e-6

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
    s.update(lk.LOOK_DEFAULTS)
    s.update({k: v for k, v in scene.render.items() if k in s})
    if s["look"] not in ("plain", "realistic"):
        raise ValueError(f"render.look: expected 'plain' or 'realistic', got {s['look']!r}")
    return s


def ball_motion(scene: Scene):
    """The tracked ball's motion: ``motion(t) -> State`` (x m, v m/s, w rad/s) at times (n,).

    Every position and spin the renderer draws comes from here, so a motion
    with cushion or ball contacts is swapped in on this one line.
    """
    ph = phases(scene.truth, scene.physics)
    return lambda t: evaluate(scene.truth, scene.physics, np.atleast_1d(np.asarray(t, float)), ph)


def quadrant_area(x, y, r):
    """Area of the disc ``X^2 + Y^2 <= r^2`` with ``X <= x`` and ``Y <= y``.

    Vectorised over ``x`` and ``y``; exact, from the primitive of the chord
    length.  ``A(x) = int_{-r}^{x} sqrt(r^2 - X^2) dX`` is half the area left
    of ``x``; for ``y >= 0`` the region below ``y`` adds ``min(y, s(X))``.
    """
    x = np.clip(x, -r, r)
    y = np.clip(y, -r, r)
    r2 = r * r

    def A(z):
        return 0.5 * (z * np.sqrt(np.maximum(r2 - z * z, 0.0)) + r2 * np.arcsin(z / r)) + 0.25 * np.pi * r2

    ya = np.abs(y)
    c = np.sqrt(np.maximum(r2 - ya * ya, 0.0))
    # int_{-r}^{x} min(|y|, s(X)) dX, in three pieces split at -c and c.
    # A is evaluated only on x and on c (each varies along one axis of a
    # patch), never on their broadcast: A(min(x, -c)) is A(x) or A(-c).
    Ax, Ac = A(x), A(c)
    m = (np.where(x <= -c, Ax, A(-c)) + ya * (np.clip(x, -c, c) + c)
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


class FrameRenderer:
    """Renders the frames of one scene with its truth.

    Parameters
    ----------
    scene : Scene
        Must carry ``truth``; the camera must be top-down (a similarity).
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
        J = homography_jacobian(self.H, scene.truth.x0)
        scale = math.sqrt(abs(np.linalg.det(J)))
        if np.abs(np.abs(J.T @ J) - scale**2 * np.eye(2)).max() > SIMILARITY_RTOL * scale**2:
            raise ValueError("camera.homography: the renderer draws only top-down "
                             "(similarity) views; the ball would image as an ellipse")
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
            self.felt = float(self.settings["felt_grey"])
            self.ball = float(self.settings["ball_grey"])

    def _nodes(self, t: np.ndarray) -> np.ndarray:
        """Exposure nodes (s) for frames at times ``t``: shape (n, K)."""
        exp = self.cam.exposure_s
        if exp <= 0:
            return t[:, None]
        # Longest blur (px) over these frames decides the node count: the
        # fastest of the exposure's ends and the strike (|v| jumps there).
        probe = np.r_[t - exp / 2, t + exp / 2, self.scene.truth.t0]
        speed = float(np.hypot(*self.motion(probe).v.T).max())
        scale = self.radius_px / self.scene.physics.R
        blur_px = (speed + 1e-9) * exp * scale
        K = int(min(MAX_BLUR_NODES, max(2, math.ceil(blur_px / BLUR_NODE_SPACING_PX))))
        offs = ((np.arange(K) + 0.5) / K - 0.5) * exp
        return t[:, None] + offs[None, :]

    def _truth(self) -> FrameTruth:
        t = frame_times(self.scene, self.n_frames).t  # the writer stamps the same times
        nodes = self._nodes(t)
        self._t_nodes = nodes
        xy_nodes = self.motion(nodes.ravel()).x
        uv_nodes = self.cam.to_pixels(xy_nodes).reshape(nodes.shape + (2,))
        self._uv_nodes = uv_nodes
        xy = self.motion(t).x
        # Top-down: the silhouette is a disc about the projected centre.
        uv = uv_nodes.mean(axis=1)
        return FrameTruth(t=t, uv=uv, xy=xy, uvc=uv.copy())

    def ball_patch(self, k: int):
        """Exact blurred coverage of frame ``k`` near the ball.

        Returns ``(cov, u0, v0)``: the coverage patch (0-1) and the pixel
        column and row of its top-left corner, clipped to the frame; ``cov``
        is None when the ball is wholly outside the frame.
        """
        uv = self._uv_nodes[k]
        r = self.radius_px
        umin = max(int(math.floor(uv[:, 0].min() - r - 1)), 0)
        vmin = max(int(math.floor(uv[:, 1].min() - r - 1)), 0)
        umax = min(int(math.ceil(uv[:, 0].max() + r + 1)), self.cam.width - 1)
        vmax = min(int(math.ceil(uv[:, 1].max() + r + 1)), self.cam.height - 1)
        if umax < umin or vmax < vmin:
            return None, 0, 0
        w, h = umax - umin + 1, vmax - vmin + 1
        cov = np.zeros((h, w))
        for cu, cv in uv:
            cov += disc_coverage(cu, cv, r, umin, vmin, w, h)
        cov /= len(uv)
        return cov, umin, vmin

    # --- realistic look ----------------------------------------------------

    def _init_realistic(self):
        s = self.settings
        cam = self.cam
        h, w = cam.height, cam.width
        self._psf = float(s["psf_sigma"])
        self._pad = int(math.ceil(4 * self._psf)) + 1 if self._psf > 0 else 0
        self._half = int(math.ceil(self.radius_px)) + 2
        self._border = 2 * self._half + self._pad + 4
        self._albedo = np.asarray(s["ball_colour"], dtype=np.float64)
        self._mark_colour = np.asarray(s["mark_colour"], dtype=np.float64)
        self._ramp = lk.ramp_image(h, w, float(s["ramp"]), float(s["ramp_angle"]))
        sharp = self._static_scene()
        B = self._border
        # Padded by B on every side, so every ball window near the frame is in range.
        self._sharp = cv2_copy_border(sharp, B)
        blur = gaussian(sharp, self._psf)
        self._blur = blur
        self.background = np.clip(np.rint(blur), 0, 255).astype(np.uint8)
        self._bg16 = self.background.astype(np.int16)
        self._frac = (blur - self.background).astype(np.float32)   # what 8 bits rounded off
        self._orient = None
        if s["markings"] != "none":
            t0 = min(0.0, float(self._t_nodes.min()))
            self._orient = lk.Orientation(lambda t: self.motion(t).w, t0, float(self._t_nodes.max()))

    def _cloth_points(self, uv: np.ndarray) -> np.ndarray:
        """Table points (m) on the cloth seen at pixels ``uv`` (..., 2)."""
        # Elementwise (a matmul with an inner size of 2 is slow on large arrays).
        Hi = np.linalg.inv(self.H)
        u, v = uv[..., 0], uv[..., 1]
        den = Hi[2, 0] * u + Hi[2, 1] * v + Hi[2, 2]
        return np.stack([(Hi[0, 0] * u + Hi[0, 1] * v + Hi[0, 2]) / den,
                         (Hi[1, 0] * u + Hi[1, 1] * v + Hi[1, 2]) / den], -1)

    def _static_scene(self) -> np.ndarray:
        """The static scene before lens blur, float32 (h, w, 3): cloth with its
        texture, cushions, rails, pockets and sights (2x2 supersampled),
        under the lighting ramp, and the other balls at rest."""
        s, cam, tb = self.settings, self.cam, self.scene.table
        h, w = cam.height, cam.width
        felt = np.asarray(s["felt_colour"], dtype=np.float32)
        names = ("cloth", "cushion", "rail", "sight", "pocket", "beyond")
        palette = np.array([felt, 0.8 * felt, s["rail_colour"], [215, 228, 235], [16, 16, 18],
                            [35, 35, 38]], np.float32)
        img = np.zeros((h, w, 3), np.float32)
        felt_share = np.zeros((h, w), np.float32)
        if s["rails"]:
            vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
            xy = self._cloth_points(np.stack([uu, vv], -1))
            # Sub-pixel samples from the local map's derivatives (one
            # projection of the whole frame, not four).
            dxy_du = np.gradient(xy, axis=1)
            dxy_dv = np.gradient(xy, axis=0)
            ss = 2
            for dy in range(ss):
                for dx in range(ss):
                    off = (np.array([dx, dy]) + 0.5) / ss - 0.5
                    layers = lk.table_layers(xy + off[0] * dxy_du + off[1] * dxy_dv,
                                             tb.length, tb.width)
                    label = np.zeros((h, w), np.uint8)
                    for i, name in enumerate(names[1:], start=1):
                        label[layers[name]] = i
                    felt_share += (label <= 1) / ss**2
                    img += palette[label] / ss**2
        else:
            img[:] = felt
            felt_share[:] = 1.0
        tex_amp = float(s["texture"])
        if tex_amp > 0:
            rng = np.random.default_rng(np.random.SeedSequence([int(s["seed"]), 7]))
            tex = lk.felt_texture((h, w), float(s["texture_scale"]), rng)
            img *= (1.0 + tex_amp * tex * felt_share)[..., None]
        img *= self._ramp[..., None]
        # Other balls at rest, lit like the tracked one, drawn with exact coverage.
        for b in s["balls"]:
            uv = cam.to_pixels(np.array([[float(b["x"]), float(b["y"])]]))
            albedo = np.asarray(b.get("colour", [228, 232, 235]), dtype=np.float64)
            self._composite_ball(img, uv, albedo, None, 0)
        return img

    def _ball_windows(self, uv: np.ndarray, albedo: np.ndarray, rots):
        """Colour and coverage of the ball at node centres ``uv`` (K, 2) (px).

        Returns ``(cov (K, n, n), colour (K, n, n, 3), iu (K,), iv (K,))``:
        each node's exact coverage and shaded colour on its own window whose
        top-left pixel is ``(iu, iv)``.  The colour is evaluated at pixel
        centres (normals clamped to the rim), the coverage is exact, so the
        silhouette's centroid stays exact.
        """
        half, r = self._half, self.radius_px
        n = 2 * half + 1
        iu = np.floor(uv[:, 0]).astype(int) - half
        iv = np.floor(uv[:, 1]).astype(int) - half
        cov = disc_coverage_batch(uv[:, 0], uv[:, 1], r, iu, iv, n)
        a = np.arange(n)
        du = (iu[:, None] + a - uv[:, 0:1])[:, None, :] * np.ones((1, n, 1))
        dv = (iv[:, None] + a - uv[:, 1:2])[:, :, None] * np.ones((1, 1, n))
        Ji = self._Jinv / self.scene.physics.R      # px -> ball radii
        nx = Ji[0, 0] * du + Ji[0, 1] * dv
        ny = Ji[1, 0] * du + Ji[1, 1] * dv
        rho2 = nx * nx + ny * ny
        shrink = np.where(rho2 > 1.0, 1.0 / np.sqrt(np.maximum(rho2, 1e-300)), 1.0)
        nx, ny = nx * shrink, ny * shrink
        nz = np.sqrt(np.maximum(1.0 - nx * nx - ny * ny, 0.0))
        normals = np.stack([nx, ny, nz], -1)
        alb = np.broadcast_to(albedo, normals.shape)
        if rots is not None and self.settings["markings"] != "none":
            body = np.einsum("kji,kabj->kabi", rots, normals)     # R^T n: table -> body
            m = lk.mark_mask(body, self.settings["markings"], r)[..., None]
            alb = alb * (1.0 - m) + self._mark_colour * m
        colour = lk.shade(normals, alb, self.settings)
        return cov, colour, iu, iv

    def _composite_ball(self, img, uv, albedo, rots, pad):
        """Draw a ball averaged over nodes ``uv`` (K, 2) into the sharp image ``img``."""
        cov, colour, iu, iv = self._ball_windows(uv, albedo, rots)
        h, w = img.shape[:2]
        n = cov.shape[1]
        K = len(uv)
        ramp = self._ramp
        for i in range(K):
            u0, v0 = iu[i] + pad, iv[i] + pad
            if u0 + n <= 0 or v0 + n <= 0 or u0 >= w or v0 >= h:
                continue
            cu = int(np.clip(uv[i, 0], 0, ramp.shape[1] - 1))
            cv = int(np.clip(uv[i, 1], 0, ramp.shape[0] - 1))
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
        uv = self._uv_nodes[k]
        B, half, pad = self._border, self._half, self._pad
        h, w = self.cam.height, self.cam.width
        vis = ((uv[:, 0] + half >= 0) & (uv[:, 0] - half <= w - 1)
               & (uv[:, 1] + half >= 0) & (uv[:, 1] - half <= h - 1))
        if not vis.any():
            return None, 0, 0
        uv = uv[vis]
        rots = self._orient(self._t_nodes[k][vis]) if self._orient is not None else None
        cov, colour, iu, iv = self._ball_windows(uv, self._albedo, rots)
        n = cov.shape[1]
        pu0, pv0 = int(iu.min()) - pad, int(iv.min()) - pad       # frame coords of the patch
        pw, ph = int(iu.max()) + n + pad - pu0, int(iv.max()) + n + pad - pv0
        sharp = self._sharp[pv0 + B:pv0 + B + ph, pu0 + B:pu0 + B + pw]
        delta = np.zeros((ph, pw, 3), np.float32)
        K = len(self._uv_nodes[k])
        ramp = self._ramp
        for i in range(len(uv)):
            a, b = iu[i] - pu0, iv[i] - pv0
            cu = int(np.clip(uv[i, 0], 0, w - 1))
            cv = int(np.clip(uv[i, 1], 0, h - 1))
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
        into the departing ball), then withdraws at 0.6 m/s.  Negative is
        past the contact point.
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
        gap = np.where(back, -f * (1 - math.exp(-3.0)) + 0.6 * (t - tr.t0 - tf), gap)
        # The tip stays behind the ball's rear point.
        d_hat = v0 / max(speed, 1e-12)
        moved = (self.motion(t).x - np.asarray(tr.x0)) @ d_hat
        return np.maximum(gap, -moved)

    def _cue_pieces(self, k: int) -> list:
        """The cue's change to the blurred background in frame ``k``: a list
        of ``(delta, u0, v0)`` patches, one per stretch of the cue (each
        pixel belongs to one stretch, so overlapping patches add exactly)."""
        if not self.settings["cue"]:
            return []
        tr = self.scene.truth
        v0 = np.asarray(tr.v0)
        speed = float(np.hypot(*v0))
        if speed <= 0:
            return []
        d = v0 / speed
        nrm = np.array([-d[1], d[0]])
        R = self.scene.physics.R
        # The cue's state at the frame's middle (its own blur is not drawn).
        tip = np.asarray(tr.x0) - d * (R + float(self.cue_tip(np.array([self.truth.t[k]]))[0]))
        px_m = self.radius_px / R
        h, w = self.cam.height, self.cam.width
        pieces = []
        step = 48.0 / px_m                      # a stretch of about 48 px
        edges = np.arange(0.0, CUE_LENGTH_M + step, step)
        edges[-1] = CUE_LENGTH_M
        pad = self._pad + 2
        for a0, a1 in zip(edges[:-1], edges[1:]):
            r1 = cue_radius(a1)
            corners = np.array([tip - d * a + nrm * c for a in (a0, a1) for c in (-r1, r1)])
            uv = self.cam.to_pixels(corners)
            u_lo = max(int(math.floor(uv[:, 0].min())) - pad, 0)
            v_lo = max(int(math.floor(uv[:, 1].min())) - pad, 0)
            u_hi = min(int(math.ceil(uv[:, 0].max())) + pad, w - 1)
            v_hi = min(int(math.ceil(uv[:, 1].max())) + pad, h - 1)
            if u_hi < u_lo or v_hi < v_lo:
                continue
            vv, uu = np.mgrid[v_lo:v_hi + 1, u_lo:u_hi + 1]
            xy = self._cloth_points(np.stack([uu, vv], -1).reshape(-1, 2).astype(float))
            rel = xy - tip
            a = -(rel @ d)                       # along the cue from its tip (m)
            c = rel @ nrm                        # across (m)
            own = (a >= a0) & (a < a1) if a0 > 0 else (a < a1)
            ra = cue_radius(np.clip(a, 0, CUE_LENGTH_M))
            cov = np.clip((ra - np.abs(c)) * px_m + 0.5, 0, 1) * np.clip(a * px_m + 0.5, 0, 1) * own
            if not cov.any():
                continue
            colour = cue_colour(a)
            across = np.clip(np.abs(c) / ra, 0, 1)
            colour = colour * (0.55 + 0.45 * np.sqrt(1 - across**2))[:, None]
            shape = vv.shape
            sharp = self._sharp[v_lo + self._border:v_hi + 1 + self._border,
                                u_lo + self._border:u_hi + 1 + self._border]
            ramp = self._ramp[v_lo:v_hi + 1, u_lo:u_hi + 1, None]
            delta = cov.reshape(shape)[..., None] * (colour.reshape(shape + (3,)) * ramp - sharp)
            pieces.append((gaussian(delta, self._psf, constant=True), u_lo, v_lo))
        return pieces

    def _render_realistic(self, k: int, rng: np.random.Generator) -> np.ndarray:
        import cv2

        if self.sigma > 0:
            u = np.frombuffer(rng.bytes(2 * self._bg16.size), dtype=np.uint16).reshape(self._bg16.shape)
            frame = cv2.add(np.take(self.lut, u), self._bg16, dtype=cv2.CV_8U)
        else:
            frame = self.background.copy()
        pieces = self._cue_pieces(k)
        delta, u0, v0 = self._ball_delta(k)
        if delta is not None:
            pieces.append((delta, u0, v0))
        # The frame is round(blur + n) with integer noise n: adding each
        # patch's change to the unrounded value keeps it round(blur + delta + n).
        for delta, u0, v0 in merge_patches(pieces):
            h, w = delta.shape[:2]
            sl = (slice(v0, v0 + h), slice(u0, u0 + w))
            clean = frame[sl] + self._frac[sl] + delta
            frame[sl] = np.clip(np.rint(clean), 0, 255).astype(np.uint8)
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
        if self.sigma > 0:
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
    ends = np.array([e for e, _ in CUE_PARTS])
    cols = np.array([c for _, c in CUE_PARTS], dtype=np.float32)
    return cols[np.minimum(np.searchsorted(ends, a), len(ends) - 1)]


def merge_patches(pieces: list) -> list:
    """Patches ``(delta, u0, v0)`` merged until none overlap (overlaps added)."""
    out = list(pieces)
    merged = True
    while merged and len(out) > 1:
        merged = False
        for i in range(len(out)):
            for j in range(i + 1, len(out)):
                (a, au, av), (b, bu, bv) = out[i], out[j]
                if (au < bu + b.shape[1] and bu < au + a.shape[1]
                        and av < bv + b.shape[0] and bv < av + a.shape[0]):
                    u0, v0 = min(au, bu), min(av, bv)
                    u1 = max(au + a.shape[1], bu + b.shape[1])
                    v1 = max(av + a.shape[0], bv + b.shape[0])
                    m = np.zeros((v1 - v0, u1 - u0, 3), np.float32)
                    m[av - v0:av - v0 + a.shape[0], au - u0:au - u0 + a.shape[1]] += a
                    m[bv - v0:bv - v0 + b.shape[0], bu - u0:bu - u0 + b.shape[1]] += b
                    out[i] = (m, u0, v0)
                    del out[j]
                    merged = True
                    break
            if merged:
                break
    return out


def gaussian(img: np.ndarray, sigma: float, constant: bool = False) -> np.ndarray:
    """Gaussian blur (the lens's PSF) of a float image; zero outside when ``constant``."""
    import cv2

    img = np.ascontiguousarray(img, dtype=np.float32)
    if sigma <= 0:
        return img
    border = cv2.BORDER_CONSTANT if constant else cv2.BORDER_REFLECT
    return cv2.GaussianBlur(img, (0, 0), sigma, borderType=border)


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
    if not left:
        end = min(end + float(s["tail"]), float(s["max_duration"]))
    return int(math.floor(end * fps)) + 1
