"""The realistic look: colour felt, rails, pockets, sights, other balls, a shaded ball.

Everything here draws *into arrays* (no files); :mod:`cuespin.render.draw`
uses it for scenes whose ``render.look`` is ``"realistic"``.  The look's
settings live in the scene's ``render`` block (the tracker never reads it);
:data:`LOOK_DEFAULTS` lists every key with its default.

Geometry of the image of a ball
-------------------------------
The ball's silhouette is drawn with exact pixel coverage (the plain look's
``disc_coverage`` on a top-down camera), and shading, highlight and markings
only modulate the colour *inside* it, so the silhouette's centroid (the
truth sidecar's ``u_px, v_px``) stays exact.  The optical blur is a
symmetric Gaussian PSF and leaves every centroid where it was.

The image's *intensity-weighted* centroid is not the centre: the light comes
from one side (``light_azimuth``, ``light_elevation``), so the lit half is
brighter and the terminator darkens the far half.  Measured with
``python benchmarks/render.py --offsets`` (centroid of ``|frame - felt|``
summed over the channels, noise-free, top-down 1280 x 720 view, ball radius
12.0 px, PSF 0.7 px, light from +u): the offset points towards the light, is
about 0.1-0.2 R, and depends on the ball/felt pair (on red on green, whose
grey contrast is tiny, the channels' differences partly cancel)::

    look                                 white/green  red/green  yellow/blue   (du px; dv < 0.002)
    matte, light overhead (86 deg)           0.27        0.07        0.16
    matte, light at 60 deg                   1.77        0.43        1.00
    matte, light at 50 deg, ambient 0.2      2.52        0.69        1.29
    highlight 0.5, light at 60 deg           1.81        0.44        1.02
    highlight 0.7, light at 50 deg           2.46        0.61        1.30

So a tracker that takes the intensity centroid (or fits a uniform disc) of a
realistic ball is off by up to 2.5 px, 200 times the truth's 0.01 px; the
centre has to come from a model of the ball's look, not its brightness.

Through a real camera (``FrameRenderer`` with a pose camera) the
silhouette's own centroid (sidecar ``u_px, v_px``) is off the projected
centre (``uc_px, vc_px``) too, measured over a 25 x 13 grid of the table
(``camera.silhouette_centroid_offset``): 1.5 m high, 15 deg tilt, k1 -0.25:
max 0.30 px, median 0.011; 2 m, 8 deg, k1 -0.1: max 0.063, median 0.044;
3 m straight down, no distortion: max 0.058, median 0.031 (perspective alone).
"""

from __future__ import annotations

import math

import numpy as np

# Ball and felt colours (BGR, 0-255) of the usual sets.  Grey level
# (0.114 B + 0.587 G + 0.299 R, OpenCV's) contrast of some pairs is under 25:
# red on green (88 vs 92), orange on grey felt, blue on blue.
BALL_COLOURS = {
    "white": (228, 232, 235),
    "yellow": (30, 205, 240),
    "red": (45, 40, 200),
    "orange": (30, 125, 240),
    "blue": (165, 75, 25),
}
FELT_COLOURS = {
    "green": (60, 130, 35),
    "blue": (150, 95, 25),
    "grey": (125, 122, 118),
    "red": (45, 45, 150),
}
RAIL_COLOURS = ((25, 55, 95), (30, 45, 70), (20, 30, 45), (60, 60, 62))   # woods, black
MARK_COLOURS = ((30, 30, 200), (25, 25, 25))                             # red, black dots

# Real table dimensions (m): cushion nose to rail, rail to outer edge,
# pocket mouths, sights (WPA: diamonds every 1/8 of the length).
CUSHION_WIDTH_M = 0.05
RAIL_WIDTH_M = 0.11
CORNER_POCKET_R_M = 0.062
SIDE_POCKET_R_M = 0.058
SIGHT_R_M = 0.009

LOOK_DEFAULTS = {
    "look": "plain",                 # "plain" (uniform grey disc) or "realistic"
    "ball_colour": [228, 232, 235],  # BGR albedo of the tracked ball
    "felt_colour": [60, 130, 35],    # BGR of the cloth
    "rail_colour": [25, 55, 95],     # BGR of the wooden rail
    "noise_sigma": 2.0,              # sensor noise per channel (levels): draw.ByteNoise, a rounded Gaussian
    "ambient": 0.35,                 # share of light that does not depend on the normal
    "light_azimuth": 0.6,            # direction of the light in the table frame (rad)
    "light_elevation": 1.1,          # above the cloth (rad); pi/2 is straight overhead
    "specular": 0.5,                 # highlight strength (0: none), fraction of 255
    "shininess": 40.0,               # Blinn exponent: larger, smaller highlight
    "psf_sigma": 0.7,                # optical blur, Gaussian PSF sigma (px)
    "texture": 0.04,                 # felt texture, relative std of brightness
    "texture_scale": 1.5,            # its correlation length (px)
    "ramp": 0.15,                    # lighting ramp: relative peak-to-peak across the frame
    "ramp_angle": 0.0,               # its direction in the image (rad)
    "rails": True,                   # cushions, rails, pockets and sights around the cloth
    "balls": [],                     # other balls at rest: [{"x", "y", "colour": [b, g, r]}]
    "markings": "none",              # "none", "dots" or "logo" on the tracked ball
    "mark_colour": [30, 30, 200],    # BGR of the markings
    "cue": False,                    # a cue along the shot line at the strike
    "cue_gap": 0.08,                 # cue tip's distance behind the ball before it moves (m)
    "cue_follow": 0.04,              # follow-through past the contact point (m)
}


def check_look(settings: dict) -> None:
    """Refuse a realistic look's settings that cannot be drawn, one line naming the key.

    Raises
    ------
    ValueError
        ``render.<key>: ...`` for a colour that is not three numbers in
        0-255, an unknown ``markings``, a negative amount, or a resting ball
        without ``x`` and ``y``.
    """
    for key in ("ball_colour", "felt_colour", "rail_colour", "mark_colour"):
        c = np.asarray(settings[key], dtype=object)
        ok = c.shape == (3,) and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                     and 0 <= v <= 255 for v in c)
        if not ok:
            raise ValueError(f"render.{key}: expected three numbers 0-255 (B, G, R), got {settings[key]!r}")
    if settings["markings"] not in ("none", "dots", "logo"):
        raise ValueError(f"render.markings: expected 'none', 'dots' or 'logo', got {settings['markings']!r}")
    for key in ("ambient", "specular", "psf_sigma", "texture", "texture_scale", "ramp", "shininess",
                "cue_gap", "cue_follow"):
        v = settings[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise ValueError(f"render.{key}: expected a number >= 0, got {v!r}")
    balls = settings["balls"]
    if not isinstance(balls, list) or not all(isinstance(b, dict) and "x" in b and "y" in b
                                              for b in balls):
        raise ValueError("render.balls: expected a list of {\"x\": m, \"y\": m, \"colour\": [b, g, r]}")


def grey_level(bgr) -> float:
    """OpenCV's BGR-to-grey weighting of a colour (levels)."""
    b, g, r = (float(c) for c in bgr)
    return 0.114 * b + 0.587 * g + 0.299 * r


def light_vectors(settings: dict):
    """Unit light direction ``L`` and Blinn half vector ``H`` (view from +z), table frame."""
    az, el = float(settings["light_azimuth"]), float(settings["light_elevation"])
    L = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    H = L + np.array([0.0, 0.0, 1.0])
    return L, H / np.linalg.norm(H)


def shade(normals: np.ndarray, albedo: np.ndarray, settings: dict, view=None) -> np.ndarray:
    """Colour (BGR, float) of the ball's surface with outward ``normals`` (..., 3).

    Lambertian diffuse ``albedo (ka + (1 - ka) max(n.L, 0))`` (darker towards
    the rim, the terminator on the side away from the light) plus a Blinn
    highlight ``255 ks max(n.H, 0)^p`` of the light's own colour; ``view``
    (..., 3), unit vectors towards the camera, default straight up.
    """
    L, H = light_vectors(settings)
    if view is not None:
        H = L + view
        H = H / np.linalg.norm(H, axis=-1, keepdims=True)
    ka = float(settings["ambient"])
    ndl = np.maximum(normals @ L, 0.0)
    out = albedo * (ka + (1.0 - ka) * ndl)[..., None]
    ks = float(settings["specular"])
    if ks > 0:
        ndh = (normals * H).sum(-1) if H.ndim > 1 else normals @ H
        spec = 255.0 * ks * np.maximum(ndh, 0.0) ** float(settings["shininess"])
        out = out + spec[..., None]
    return out


# --- orientation of a spinning ball --------------------------------------

def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a b`` of quaternions ``(w, x, y, z)``, broadcast."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def quat_from_rotvec(r: np.ndarray) -> np.ndarray:
    """Quaternions of rotation vectors ``r`` (..., 3) (axis times angle, rad)."""
    th = np.linalg.norm(r, axis=-1, keepdims=True)
    # sin(th/2)/th, with its limit 1/2 at th -> 0.
    s = np.where(th > 1e-12, np.sin(0.5 * th) / np.maximum(th, 1e-300), 0.5)
    return np.concatenate([np.cos(0.5 * th), r * s], axis=-1)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4)."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def prefix_product(dq: np.ndarray) -> np.ndarray:
    """``Q[i] = dq[i] dq[i-1] ... dq[0]`` for every ``i`` (later rotations on the left).

    Hillis-Steele scan: log2(n) vectorised steps instead of n Python ones.
    """
    # Components as rows (4, n): each step's products and sums run on
    # contiguous rows with no stacking; the same arithmetic, in the same
    # order, as quat_mul and the norm on (n, 4).
    q = np.ascontiguousarray(dq.T)
    d = 1
    while d < q.shape[1]:
        (aw, ax, ay, az), (bw, bx, by, bz) = q[:, d:], q[:, :-d]
        q[:, d:] = [aw * bw - ax * bx - ay * by - az * bz,
                    aw * bx + ax * bw + ay * bz - az * by,
                    aw * by - ax * bz + ay * bw + az * bx,
                    aw * bz + ax * by - ay * bx + az * bw]
        q /= np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        d *= 2
    return np.ascontiguousarray(q.T)


# Largest rotation (rad) of one integration step: the midpoint rule's error
# per step is O(|w'| dt^3), far below a pixel's angle on the ball; where w
# jumps (the strike) the step that straddles the jump is off by at most this
# angle (0.03 px on the rim of a 14-px ball).
ORIENT_STEP_RAD = 0.002
MAX_ORIENT_STEPS = 2_000_000


class Orientation:
    """Body-to-table rotation of a spinning ball at any time.

    Integrates ``dR/dt = [w(t)]x R`` from ``R(t_start) = I`` on a grid fine
    enough that each step turns the ball by at most ``ORIENT_STEP_RAD``
    (midpoint rule), with ``w`` the forward model's planar angular velocity
    (its z part is not modelled and taken as 0).

    Parameters
    ----------
    spin : callable
        ``spin(t)`` -> angular velocity (rad/s), shape (n, 2), at times (n,).
    t_start, t_end : float
        Span of times (s) that will be asked for.
    """

    def __init__(self, spin, t_start: float, t_end: float):
        self.spin = spin
        probe = np.linspace(t_start, t_end, 8192)
        wmax = max(float(np.hypot(*spin(probe).T).max()), 1e-9)
        n = int(min(MAX_ORIENT_STEPS, max(1, math.ceil((t_end - t_start) * wmax / ORIENT_STEP_RAD))))
        self.grid = np.linspace(t_start, t_end, n + 1)
        dt = np.diff(self.grid)
        w_mid = spin(0.5 * (self.grid[1:] + self.grid[:-1]))
        rv = np.c_[w_mid * dt[:, None], np.zeros(n)]
        self.Q = np.concatenate([[[1.0, 0.0, 0.0, 0.0]], prefix_product(quat_from_rotvec(rv))])

    def __call__(self, t) -> np.ndarray:
        """Rotation matrices, shape ``t.shape + (3, 3)``, at times ``t`` (s)."""
        t = np.asarray(t, dtype=float)
        flat = t.ravel()
        n = len(self.grid) - 1
        k = np.clip(np.searchsorted(self.grid, flat, side="right") - 1, 0, n)
        # The last bit from the grid point to the time asked, at its own w.
        rest = np.c_[self.spin(flat) * (flat - self.grid[k])[:, None], np.zeros(len(flat))]
        q = quat_mul(quat_from_rotvec(rest), self.Q[k])
        return quat_to_matrix(q).reshape(t.shape + (3, 3))


def marks(kind: str) -> list[tuple[np.ndarray, float]]:
    """Markings in the ball's body frame: ``[(unit centre, angular radius rad)]``.

    ``dots``: six small dots on the axes (a measles training ball);
    ``logo``: one large disc and a small one beside it (a maker's mark).
    """
    if kind == "dots":
        e = np.eye(3)
        return [(s * e[i], 0.17) for i in range(3) for s in (1.0, -1.0)]
    if kind == "logo":
        side = np.array([math.sin(0.55), 0.0, math.cos(0.55)])
        return [(np.array([0.0, 0.0, 1.0]), 0.33), (side, 0.12)]
    return []


def mark_mask(normals_body: np.ndarray, kind: str, radius_px: float) -> np.ndarray:
    """Fraction (0-1) of each pixel a marking covers; edges antialiased over one pixel."""
    out = np.zeros(normals_body.shape[:-1])
    flat = out.reshape(-1)
    for c, a in marks(kind):
        cos_ang = (normals_body @ c).reshape(-1)
        # A mark covers nothing farther than a + 0.5 / radius_px from its
        # centre (the clip gives exactly 0 there): the arc cosine only on the
        # points nearer (1e-6 rad to spare against rounding; a few percent
        # of a ball's window).
        near = np.flatnonzero(cos_ang > math.cos(a + 0.5 / radius_px + 1e-6))
        ang = np.arccos(np.clip(cos_ang[near], -1.0, 1.0))
        flat[near] = np.maximum(flat[near], np.clip((a - ang) * radius_px + 0.5, 0.0, 1.0))
    return out


# --- static scene: cloth, cushions, rails, pockets, sights ----------------

def pockets(length: float, width: float) -> list[tuple[float, float, float]]:
    """Pocket centres and radii (m), table frame: four corners and two sides."""
    c, s = CORNER_POCKET_R_M, SIDE_POCKET_R_M
    d = 0.5 * c   # corner pocket centres sit just outside the corner, on the diagonal
    return [(-d, -d, c), (length + d, -d, c), (-d, width + d, c), (length + d, width + d, c),
            (0.5 * length, -0.6 * s, s), (0.5 * length, width + 0.6 * s, s)]


def sights(length: float, width: float) -> np.ndarray:
    """Diamond sights (m) on the rails' centre lines: every 1/8 of the length, 1/4 of the width."""
    off = CUSHION_WIDTH_M + 0.5 * RAIL_WIDTH_M
    pts = []
    for k in range(1, 8):
        if k != 4:
            pts += [(k * length / 8, -off), (k * length / 8, width + off)]
    for k in range(1, 4):
        pts += [(-off, k * width / 4), (length + off, k * width / 4)]
    return np.array(pts)


def table_layers(xy: np.ndarray, length: float, width: float) -> dict[str, np.ndarray]:
    """Boolean masks of the table's parts at table points ``xy`` (..., 2) on the cloth's plane."""
    x, y = xy[..., 0], xy[..., 1]
    dx = np.maximum(np.maximum(-x, x - length), 0.0)
    dy = np.maximum(np.maximum(-y, y - width), 0.0)
    out = np.maximum(dx, dy)                      # distance outside the playing surface (m)
    cushion = (out > 0) & (out <= CUSHION_WIDTH_M)
    rail = (out > CUSHION_WIDTH_M) & (out <= CUSHION_WIDTH_M + RAIL_WIDTH_M)
    pocket = np.zeros(x.shape, dtype=bool)
    for px, py, r in pockets(length, width):
        near = out < 2 * r          # pockets lie at the edge: test only the points near it
        pocket[near] |= (x[near] - px) ** 2 + (y[near] - py) ** 2 <= r * r
    sight = np.zeros(x.shape, dtype=bool)
    xs, ys = x[rail], y[rail]
    hit = np.zeros(xs.shape, dtype=bool)
    for px, py in sights(length, width):
        hit |= (np.abs(xs - px) + np.abs(ys - py)) <= SIGHT_R_M   # a diamond
    sight[rail] = hit
    beyond = out > CUSHION_WIDTH_M + RAIL_WIDTH_M
    return {"cushion": cushion & ~pocket, "rail": rail & ~pocket & ~sight,
            "sight": sight & ~pocket, "pocket": pocket, "beyond": beyond & ~pocket}


# Table parts' labels (:func:`table_labels`), in the order their masks were
# painted: later parts win, and the masks are disjoint.
TABLE_PARTS = ("cloth", "cushion", "rail", "sight", "pocket", "beyond")


def table_labels(x: np.ndarray, y: np.ndarray, length: float, width: float) -> np.ndarray:
    """The part of the table (index into :data:`TABLE_PARTS`, uint8) at table
    points ``x, y`` (m, same shape) on the cloth's plane.

    The labels of :func:`table_layers`' masks, each decided by the same
    arithmetic, in fewer passes: the part from the distance outside the
    playing surface in three comparisons, the pockets tested only on points
    in a box about them, the sights only on points near the rails' centre line.
    """
    shape = np.shape(x)
    x, y = np.ravel(x), np.ravel(y)
    dx = np.maximum(np.maximum(-x, x - length), 0.0)
    dy = np.maximum(np.maximum(-y, y - width), 0.0)
    out = np.maximum(dx, dy)                      # distance outside the playing surface (m)
    # 0 cloth, 1 cushion (0 < out <= C), 2 rail (C < out <= C + W), 5 beyond.
    lab = (out > 0).view(np.uint8).copy()
    lab += out > CUSHION_WIDTH_M
    lab += 3 * (out > CUSHION_WIDTH_M + RAIL_WIDTH_M).view(np.uint8)
    # Sights: diamonds of radius SIGHT_R_M centred on the rails' centre line
    # away from the corners (where out is the distance across the rail), so
    # a point farther than twice that from the line is in none.
    off = CUSHION_WIDTH_M + 0.5 * RAIL_WIDTH_M
    near = np.flatnonzero((lab == 2) & (np.abs(out - off) <= 2 * SIGHT_R_M))
    if near.size:
        xs, ys = x[near], y[near]
        hit = np.zeros(xs.shape, dtype=bool)
        for px, py in sights(length, width):
            hit |= (np.abs(xs - px) + np.abs(ys - py)) <= SIGHT_R_M   # a diamond
        lab[near[hit]] = 3
    # Pockets win over every other part; a pocket's disc lies in its box.
    # Every box lies past one of two lines across the table (the pockets
    # sit on the long rails): one pass finds the points that may be in a
    # box, and each box is tested on those only (1 um to spare: the points
    # passed over are farther than 2 r from every pocket's centre line).
    pk = pockets(length, width)
    y_low = max(py + 2 * r for _, py, r in pk if py < 0.5 * width) + 1e-6
    y_high = min(py - 2 * r for _, py, r in pk if py >= 0.5 * width) - 1e-6
    cand = np.flatnonzero((y <= y_low) | (y >= y_high))
    for px, py, r in pk:
        box = cand[np.abs(x[cand] - px) <= 2 * r]
        box = box[np.abs(y[box] - py) <= 2 * r]
        if box.size:
            xs, ys = x[box], y[box]
            inside = (out[box] < 2 * r) & ((xs - px) ** 2 + (ys - py) ** 2 <= r * r)
            lab[box[inside]] = 4
    return lab.reshape(shape)


def felt_texture(shape: tuple[int, int], scale: float, rng: np.random.Generator) -> np.ndarray:
    """Unit-variance Gaussian texture correlated over ``scale`` px."""
    import cv2

    tex = rng.standard_normal(shape).astype(np.float32)
    if scale > 0:
        tex = cv2.GaussianBlur(tex, (0, 0), float(scale))
    return tex / max(float(tex.std()), 1e-12)


def ramp_image(h: int, w: int, ramp: float, angle: float) -> np.ndarray:
    """Multiplicative lighting ramp ``1 + ramp * p``, ``p`` in [-1/2, 1/2] across the frame."""
    # A row of u and a column of v broadcast, then in place: one full-frame
    # pass where two grids took eight, each pixel's float32 arithmetic the same.
    pu = (np.arange(w, dtype=np.float32) - (w - 1) / 2) * math.cos(angle)
    pv = (np.arange(h, dtype=np.float32)[:, None] - (h - 1) / 2) * math.sin(angle)
    p = pu + pv
    # Rounding is monotone: the largest (smallest) sum is that of the largest
    # (smallest) terms, so the extremes need no pass over the frame.
    span = max(float((pu.max() + pv.max()) - (pu.min() + pv.min())), 1.0)
    p *= float(ramp)
    p /= span
    p += 1.0
    return p
