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
