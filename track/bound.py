"""Cramer-Rao bound for locating the ball in one rendered frame.

Computed numerically from the rendered image's derivatives: the renderer's
exact-coverage disc, averaged over its exposure nodes, differentiated by
central differences with respect to the centre (all nodes shifted), the
contrast and, when the tracker fits it, the blur vector (nuisances).  Noise
is the sensor's Gaussian plus 8-bit rounding (variance ``sigma^2 + 1/12``).
"""

from __future__ import annotations

import numpy as np

from cuespin.render.draw import disc_coverage

_STEP_PX = 1e-3



def _window(uv_nodes, radius_px: float):
    """The blur nodes' mean centre, their offsets from it, and the square
    window (top-left column and row, side in px) that holds the smeared ball
    with 3 px to spare."""
    uv_nodes = np.asarray(uv_nodes, dtype=float)
    centre = uv_nodes.mean(axis=0)
    offs = uv_nodes - centre
    half = int(np.ceil(radius_px + np.abs(offs).max() + 3))
    return centre, offs, int(round(centre[0])) - half, int(round(centre[1])) - half, 2 * half + 1

def centroid_crb(uv_nodes: np.ndarray, radius_px: float, ball_grey: float, felt: np.ndarray,
                 sigma: float, fit_blur: bool) -> np.ndarray:
    """Per-axis standard-deviation bound (px) for the centre of one frame's ball.

    Parameters
    ----------
    uv_nodes : ndarray, shape (K, 2)
        The renderer's exposure nodes for the frame (px).
    radius_px : float
        Ball radius (px).
    ball_grey : float
        The ball's grey level.
    felt : ndarray, shape (height, width)
        The rendered background (grey levels); the ball hides it.
    sigma : float
        Sensor noise (grey levels), before 8-bit rounding.
    fit_blur : bool
        Whether the blur vector is a nuisance parameter (the tracker fits it).

    Returns
    -------
    ndarray, shape (2,)
        ``sqrt`` of the diagonal of the inverse Fisher information for
        ``(u, v)`` (px).
    """
    centre, offs, u0, v0, n = _window(uv_nodes, radius_px)
    contrast = (ball_grey - np.asarray(felt, dtype=float)[v0:v0 + n, u0:u0 + n]).ravel()

    taus = (np.arange(len(offs)) + 0.5) / len(offs) - 0.5  # the nodes are in time order

    def image(c, db=(0.0, 0.0)):
        nodes = c + offs + np.outer(taus, db)
        return np.mean([disc_coverage(p[0], p[1], radius_px, u0, v0, n, n) for p in nodes], axis=0)

    cols = []
    for d in (np.array([_STEP_PX, 0.0]), np.array([0.0, _STEP_PX])):
        cols.append(contrast * (image(centre + d) - image(centre - d)).ravel() / (2 * _STEP_PX))
    cols.append(image(centre).ravel())  # d/d(ball grey)
    if fit_blur and len(offs) > 1:
        # The blur vector (start to end of the exposure) as a nuisance.
        for d in (np.array([_STEP_PX, 0.0]), np.array([0.0, _STEP_PX])):
            cols.append(contrast * (image(centre, d) - image(centre, -d)).ravel() / (2 * _STEP_PX))
    J = np.stack(cols, axis=1)
    fisher = J.T @ J / (sigma**2 + 1.0 / 12.0)
    return np.sqrt(np.diag(np.linalg.inv(fisher))[:2])


def centroid_crb_colour(uv_nodes: np.ndarray, radius_px: float, ball_bgr, felt_bgr: np.ndarray,
                        noise_cov: np.ndarray, fit_blur: bool) -> np.ndarray:
    """Per-axis bound (px) for the centre of one colour frame's ball.

    The same rendered image as :func:`centroid_crb`, in every channel: each
    pixel's three channels are one measurement with covariance
    ``noise_cov + I/12`` (8-bit rounding per channel), so the information is
    ``sum over pixels of J_p^T C^-1 J_p``.  Nuisances: the ball's colour
    (one level per channel) and, where the tracker fits it, the blur vector.

    Parameters
    ----------
    uv_nodes : ndarray, shape (K, 2)
        The exposure's nodes (px).
    radius_px : float
    ball_bgr : array_like, shape (3,)
        The ball's colour (levels).
    felt_bgr : ndarray, shape (height, width, 3)
        The felt the ball hides (levels).
    noise_cov : ndarray, shape (3, 3)
        Sensor noise covariance per pixel (levels^2), before rounding.
    fit_blur : bool

    Returns
    -------
    ndarray, shape (2,)
    """
    centre, offs, u0, v0, n = _window(uv_nodes, radius_px)
    felt = np.asarray(felt_bgr, dtype=float)[v0:v0 + n, u0:u0 + n].reshape(-1, 3)
    contrast = np.asarray(ball_bgr, float)[None, :] - felt            # (m, 3)
    taus = (np.arange(len(offs)) + 0.5) / len(offs) - 0.5

    def image(c, db=(0.0, 0.0)):
        nodes = c + offs + np.outer(taus, db)
        return np.mean([disc_coverage(p[0], p[1], radius_px, u0, v0, n, n) for p in nodes], axis=0).ravel()

    cols = []  # each (m, 3): the derivative of every pixel's three channels
    for d in (np.array([_STEP_PX, 0.0]), np.array([0.0, _STEP_PX])):
        cols.append(contrast * ((image(centre + d) - image(centre - d)) / (2 * _STEP_PX))[:, None])
    cov0 = image(centre)
    for ch in range(3):  # the ball's level in each channel
        col = np.zeros_like(contrast)
        col[:, ch] = cov0
        cols.append(col)
    if fit_blur and len(offs) > 1:
        for d in (np.array([_STEP_PX, 0.0]), np.array([0.0, _STEP_PX])):
            cols.append(contrast * ((image(centre, d) - image(centre, -d)) / (2 * _STEP_PX))[:, None])
    J = np.stack(cols, axis=2)                                         # (m, 3, p)
    Cinv = np.linalg.inv(np.asarray(noise_cov, float) + np.eye(3) / 12.0)
    fisher = np.einsum("mcp,cd,mdq->pq", J, Cinv, J)
    return np.sqrt(np.diag(np.linalg.inv(fisher))[:2])


def centroid_crb_outline(xy_nodes, camera, R: float, ball_grey: float, felt: np.ndarray,
                         sigma: float, fit_blur: bool) -> np.ndarray:
    """Covariance bound (px^2) for the projected centre of one frame's ball under any camera.

    The renderer's image of the ball through ``camera``: the sphere's
    silhouette at each exposure node (its ``OUTLINE_VERTICES``-gon, exact
    coverage), averaged.  The parameters are a shift of the whole image (the
    centre; the outline's shape changes by ~1e-3 px per px of shift, which
    carries no usable information), the ball's grey level and, where the
    tracker fits it, the blur vector (node ``k`` shifted by ``tau_k`` times
    it).  Noise as in :func:`centroid_crb`.

    Parameters
    ----------
    xy_nodes : ndarray, shape (K, 2)
        The exposure's nodes on the table (m).
    camera : Camera
    R : float
        Ball radius (m).
    ball_grey : float
    felt : ndarray, shape (height, width)
        The rendered background (grey levels).
    sigma : float
        Sensor noise (grey levels), before 8-bit rounding.
    fit_blur : bool

    Returns
    -------
    ndarray, shape (2, 2)
        Inverse Fisher information's ``(u, v)`` block (px^2); convert with
        ``camera.cov_to_table``.
    """
    from cuespin.render.draw import OUTLINE_VERTICES, polygon_coverage_batch

    polys = camera.ball_outline(np.atleast_2d(xy_nodes), R, OUTLINE_VERTICES)      # (K, n, 2)
    K = len(polys)
    lo, hi = polys.reshape(-1, 2).min(axis=0), polys.reshape(-1, 2).max(axis=0)
    u0, v0 = int(np.floor(lo[0])) - 3, int(np.floor(lo[1])) - 3
    w, h = int(np.ceil(hi[0])) + 4 - u0, int(np.ceil(hi[1])) + 4 - v0
    contrast = (ball_grey - np.asarray(felt, dtype=float)[v0:v0 + h, u0:u0 + w]).ravel()
    taus = (np.arange(K) + 0.5) / K - 0.5

    def image(d, db=(0.0, 0.0)):
        shift = np.asarray(d, float)[None, :] + np.outer(taus, db)                  # (K, 2)
        cov = polygon_coverage_batch(polys + shift[:, None, :], np.full(K, u0), np.full(K, v0), w, h)
        return cov.mean(axis=0).ravel()

    cols = []
    for d in (np.array([_STEP_PX, 0.0]), np.array([0.0, _STEP_PX])):
        cols.append(contrast * (image(d) - image(-d)) / (2 * _STEP_PX))
    cols.append(image(np.zeros(2)))
    if fit_blur and K > 1:
        for d in (np.array([_STEP_PX, 0.0]), np.array([0.0, _STEP_PX])):
            cols.append(contrast * (image(np.zeros(2), d) - image(np.zeros(2), -d)) / (2 * _STEP_PX))
    J = np.stack(cols, axis=1)
    fisher = J.T @ J / (sigma**2 + 1.0 / 12.0)
    return np.linalg.inv(fisher)[:2, :2]


# Central-difference steps for the realistic look's nuisances: light angles
# and marking turns (rad), ambient and highlight strength (fractions), the
# lens's PSF sigma (px), the albedo (levels).
_LOOK_STEPS = {"ambient": 1e-3, "light_azimuth": 1e-3, "light_elevation": 1e-3, "specular": 1e-3,
               "psf_sigma": 1e-3}
_ALBEDO_STEP = 0.05
_TURN_STEP = 1e-3
# A pixel the markings change by more than this (levels) depends on their
# pattern: far below the noise (1-8 levels) and 8-bit rounding (0.29), and
# far above float32 rounding of the rendered levels (~1e-5).
MARK_SUPPORT_LEVELS = 1e-3


def realistic_nuisances(settings: dict, fit_blur: bool, pattern_known: bool = False) -> list[str]:
    """The realistic look's nuisance parameters a tracker that learns the
    ball's look from the video does not know: the ball's albedo (one per
    channel), the ambient share, the light's two angles, the highlight's
    strength (when there is one), the lens's PSF width (when there is
    blur), with ``pattern_known`` the markings' orientation (three turns,
    when there are markings; without it the markings' pixels are left out
    instead, :func:`realistic_image_jacobian`) and, where the tracker fits
    it, the blur vector."""
    names = ["albedo_b", "albedo_g", "albedo_r", "ambient", "light_azimuth", "light_elevation"]
    if float(settings["specular"]) > 0:
        names.append("specular")
    if float(settings["psf_sigma"]) > 0:
        names.append("psf_sigma")
    if pattern_known and settings["markings"] != "none":
        names += ["turn_x", "turn_y", "turn_z"]
    if fit_blur:
        names += ["blur_u", "blur_v"]
    return names


def realistic_image_jacobian(renderer, k: int, fit_blur: bool = False, pattern_known: bool = False):
    """Derivatives of the realistic look's noise-free colour image of frame ``k``.

    The image near the ball is the blurred static scene plus the ball's
    change to it (``FrameRenderer._delta_of``: exact coverage, shading,
    highlight, markings at the frame's orientation, lens PSF), drawn again
    for each parameter moved up and down (central differences): the
    centre (every exposure node shifted by the same pixels, and its table
    position with it), then :func:`realistic_nuisances`.  The static scene
    under the ball is known (the tracker learns the felt from the video).
    Top-down (similarity) cameras only.

    Markings: a tracker that does not know the markings' pattern (dots or a
    logo: where on the ball, what shape) cannot use their edges.  Unknown,
    the pattern is a free level (per channel) for every pixel it changes:
    the Fisher information of ``(centre, nuisances, free levels)`` restricted
    to the centre and nuisances by the Schur complement is that of the other
    pixels alone (each free level's column is its own pixel's indicator, so
    it absorbs that pixel's row), so those pixels' rows are set to zero
    (``pattern_known`` False, the default: the pixels the markings change
    by more than ``MARK_SUPPORT_LEVELS``, every exposure node's markings at
    the frame's orientation).  Knowing which pixels they are is still more
    than a tracker knows, so this stays a lower bound for one that finds
    them.  With ``pattern_known`` the pattern is known and only its
    orientation (three turns) is a nuisance: the bound of a tracker that
    matches the dots themselves, which the dots' sharp edges make 2-10
    times lower (docs/measurements.md).

    Returns
    -------
    (J, names) : (ndarray, shape (m, 3, p), list of str)
        Per pixel of a window holding the ball, the change of its B, G, R
        levels per unit of each parameter (px for the centre).
    """
    import copy

    from cuespin.render import look as lk

    if not renderer.similar:
        raise ValueError("realistic_image_jacobian: top-down (similarity) cameras only")
    uv, xy, t = renderer._uv_nodes[k], renderer._xy_nodes[k], renderer._t_nodes[k]
    K = len(uv)
    taus = (np.arange(K) + 0.5) / K - 0.5
    Jinv = renderer._Jinv
    half = renderer._half + renderer._pad + 4
    centre = uv.mean(axis=0)
    offs = uv - centre
    U0 = int(np.floor(centre[0] + offs[:, 0].min())) - half
    V0 = int(np.floor(centre[1] + offs[:, 1].min())) - half
    W = int(np.ceil(np.ptp(offs[:, 0]))) + 2 * half + 2
    Hh = int(np.ceil(np.ptp(offs[:, 1]))) + 2 * half + 2
    settings0 = renderer.settings
    albedo0 = np.asarray(renderer._albedo, float)
    orient = renderer._orient
    names = realistic_nuisances(settings0, fit_blur, pattern_known)

    def image(d_uv=np.zeros(2), d_blur=np.zeros(2), albedo=albedo0, settings=None, turn=None, marked=True):
        """The ball's change to the scene on the fixed window, with the parameters moved."""
        shift = d_uv[None, :] + np.outer(taus, d_blur)
        nodes_uv = uv + shift
        nodes_xy = xy + shift @ Jinv.T
        rot = orient if marked else None
        if turn is not None and orient is not None:
            Rt = lk.quat_to_matrix(lk.quat_from_rotvec(np.asarray(turn, float)))

            def rot(tt):
                return Rt @ orient(tt)
        r = renderer
        if settings is not None:
            r = copy.copy(renderer)
            r.settings = settings
            r._psf = float(settings["psf_sigma"])
        delta, a0, b0 = r._delta_of(nodes_uv, nodes_xy, albedo, None if rot is None else rot(t))
        out = np.zeros((Hh, W, 3))
        if delta is None:
            return out
        ys, xs = b0 - V0, a0 - U0
        h, w = delta.shape[:2]
        y0, x0 = max(ys, 0), max(xs, 0)
        y1, x1 = min(ys + h, Hh), min(xs + w, W)
        out[y0:y1, x0:x1] = delta[y0 - ys:y1 - ys, x0 - xs:x1 - xs]
        return out

    cols = []
    for d in (np.array([_STEP_PX, 0.0]), np.array([0.0, _STEP_PX])):
        cols.append((image(d_uv=d) - image(d_uv=-d)) / (2 * _STEP_PX))
    for name in names:
        if name.startswith("albedo"):
            e = np.zeros(3)
            e["bgr".index(name[-1])] = _ALBEDO_STEP
            col = (image(albedo=albedo0 + e) - image(albedo=albedo0 - e)) / (2 * _ALBEDO_STEP)
        elif name.startswith("turn"):
            e = np.zeros(3)
            e["xyz".index(name[-1])] = _TURN_STEP
            col = (image(turn=e) - image(turn=-e)) / (2 * _TURN_STEP)
        elif name.startswith("blur"):
            e = np.array([_STEP_PX, 0.0]) if name == "blur_u" else np.array([0.0, _STEP_PX])
            col = (image(d_blur=e) - image(d_blur=-e)) / (2 * _STEP_PX)
        else:
            h = _LOOK_STEPS[name]
            up, down = dict(settings0), dict(settings0)
            up[name] = float(settings0[name]) + h
            down[name] = float(settings0[name]) - h
            col = (image(settings=up) - image(settings=down)) / (2 * h)
        cols.append(col)
    J = np.stack([c.reshape(-1, 3) for c in cols], axis=2)
    if not pattern_known and orient is not None:
        support = np.abs(image() - image(marked=False)).max(axis=2) > MARK_SUPPORT_LEVELS
        J[support.ravel()] = 0.0
    return J, ["cu", "cv"] + names


def centroid_crb_realistic(renderer, k: int, fit_blur: bool = False, grey_weights=None,
                           pattern_known: bool = False) -> np.ndarray:
    """Per-axis Cramer-Rao bound (px) for the ball's centre in frame ``k`` of a realistic render.

    From :func:`realistic_image_jacobian` (every channel, the look's
    nuisance parameters; markings of unknown pattern unless
    ``pattern_known``), with the renderer's noise: ``noise_sigma`` per
    channel, independent, plus 8-bit rounding (1/12 per channel).  With
    ``grey_weights`` (B, G, R weights, e.g. OpenCV's luma 0.114, 0.587,
    0.299) the bound of a tracker that sees only that one channel of the
    same frames (its noise ``|w|^2 sigma^2`` plus the grey frame's own
    rounding, 1/12).

    Returns
    -------
    ndarray, shape (2,)
    """
    J, _ = realistic_image_jacobian(renderer, k, fit_blur, pattern_known)
    s2 = float(renderer.sigma) ** 2
    if grey_weights is None:
        fisher = np.einsum("mcp,mcq->pq", J, J) / (s2 + 1.0 / 12.0)
    else:
        w = np.asarray(grey_weights, float)
        Jg = np.einsum("mcp,c->mp", J, w)
        fisher = Jg.T @ Jg / (s2 * float(w @ w) + 1.0 / 12.0)
    # Columns in very different units: invert the correlation-scaled matrix.
    d = np.sqrt(np.diag(fisher))
    d[d == 0] = 1.0
    inv = np.linalg.pinv(fisher / np.outer(d, d)) / np.outer(d, d)
    return np.sqrt(np.diag(inv)[:2])
