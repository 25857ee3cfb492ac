"""Drawing frames of a scene: exact-coverage disc, motion blur, noise, 8 bits.

The ball is a disc of uniform grey on a felt background.  Each pixel takes
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

from cuespin.physics.contact import scene_trajectory
from cuespin.physics.motion import Phases, phases
from cuespin.physics.scene import Scene, homography_jacobian, motion_end
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
    """The scene's ``render`` block with every default filled in."""
    s = dict(RENDER_DEFAULTS)
    s.update({k: v for k, v in scene.render.items() if k in RENDER_DEFAULTS})
    return s


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
    """Truth for frame ``k``: the ball's image centroid (px), averaged over the
    exposure, and its true centre (m) at the frame's timestamp."""

    t: np.ndarray
    uv: np.ndarray
    xy: np.ndarray


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
        self.cam = scene.camera
        self.H = self.cam.H
        self.ph: Phases = phases(scene.truth, scene.physics)
        # The path, continued past contacts when render.contacts is on (physics/contact.py).
        self.trajectory = scene_trajectory(scene)
        J = homography_jacobian(self.H, scene.truth.x0)
        scale = math.sqrt(abs(np.linalg.det(J)))
        if np.abs(np.abs(J.T @ J) - scale**2 * np.eye(2)).max() > SIMILARITY_RTOL * scale**2:
            raise ValueError("camera.homography: the renderer draws only top-down "
                             "(similarity) views; the ball would image as an ellipse")
        self.radius_px = scene.physics.R * scale
        self.n_frames = n_frames if n_frames is not None else video_length(scene)
        self.background = make_background(scene, self.settings)
        self.sigma = float(self.settings["noise_sigma"])
        self.lut = noise_lut(self.sigma)
        self.felt = float(self.settings["felt_grey"])
        self.ball = float(self.settings["ball_grey"])
        self.truth = self._truth()

    def _nodes(self, t: np.ndarray) -> np.ndarray:
        """Exposure nodes (s) for frames at times ``t``: shape (n, K)."""
        exp = self.cam.exposure_s
        if exp <= 0:
            return t[:, None]
        # Longest blur (px) over these frames decides the node count.
        # |v| is convex while sliding and falls while rolling: its maximum is at t0 or t1.
        speed = max(np.hypot(*self.ph.v0), np.hypot(*self.ph.v1))
        scale = self.radius_px / self.scene.physics.R
        blur_px = (speed + 1e-9) * exp * scale
        K = int(min(MAX_BLUR_NODES, max(2, math.ceil(blur_px / BLUR_NODE_SPACING_PX))))
        offs = ((np.arange(K) + 0.5) / K - 0.5) * exp
        return t[:, None] + offs[None, :]

    def _truth(self) -> FrameTruth:
        t = frame_times(self.scene, self.n_frames).t  # the writer stamps the same times
        nodes = self._nodes(t)
        xy_nodes = self.trajectory.positions(nodes.ravel())
        uv_nodes = self.cam.to_pixels(xy_nodes).reshape(nodes.shape + (2,))
        self._uv_nodes = uv_nodes
        xy = self.trajectory.positions(t)
        return FrameTruth(t=t, uv=uv_nodes.mean(axis=1), xy=xy)

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

    def render(self, k: int, rng: np.random.Generator) -> np.ndarray:
        """Frame ``k`` as an 8-bit grey image, shape (height, width).

        Parameters
        ----------
        k : int
            Frame index.
        rng : numpy.random.Generator
            Noise source; frames drawn in order from one generator are
            independent.
        """
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
