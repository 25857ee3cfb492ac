"""The ball's local outline under perspective: an ellipse, and its exact pixel coverage.

Through a tilted camera the ball's image is a sphere's silhouette: an exact
conic for a pinhole (the cone of rays tangent to the sphere cut by the image
plane), through a lens nearly one.  Its size and shape vary across the
image, so one disc at the image-centre scale misfits it (measured: centre
RMS 0.55 px and stated errors 4.3x too small at 1.5 m, 15 degrees).  Here
the camera gives the outline at the ball's predicted table position
(:meth:`~cuespin.physics.camera.Camera.ball_outline`), an ellipse with the
same area moments stands for it, and :func:`ellipse_with_gradient` gives
that ellipse's exact pixel coverage and its derivatives in the centre (the
counterpart of :func:`cuespin.track.model.disc_with_gradient`).  The fit
then locates the ellipse's centre, the silhouette's centroid (equal for an
ellipse), and :mod:`cuespin.track.projection` moves it to the projected
centre with the camera's offset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Vertices of the outline polygon whose area moments give the ellipse (an
# inscribed polygon's moments are too small by O(1/n^2), corrected by
# _inscribed): 256 for one outline, half that for the grid of OutlineGrid.
OUTLINE_VERTICES = 256
# An outline whose ellipse departs from the tracker's disc by less than this
# (px, on either semi-axis, and in orientation-weighted shear) is fitted as
# that disc: 1e-3 px moves no centre measurably (the bound is >= 2e-3 px at
# the lowest noise benchmarked) and keeps similarity cameras on the disc.
CIRCLE_TOL_PX = 1e-3


@dataclass(frozen=True)
class Ellipse:
    """An ellipse about its centre: points ``d`` (px) with ``d^T Q d <= 1``.

    Attributes
    ----------
    Q : tuple of tuple, shape (2, 2)
        Symmetric positive-definite shape matrix (1/px^2); ``Q = I / r^2``
        for a disc of radius ``r``.
    """

    Q: tuple

    @property
    def Qm(self) -> np.ndarray:
        return np.asarray(self.Q, float)

    @property
    def half_extent(self) -> np.ndarray:
        """Half-widths of the bounding box ``(du, dv)`` (px)."""
        Qi = np.linalg.inv(self.Qm)
        return np.sqrt(np.diag(Qi))

    @property
    def radius(self) -> float:
        """Radius of the disc of the same area (px)."""
        return float(np.linalg.det(self.Qm) ** -0.25)

    @property
    def max_radius(self) -> float:
        """Largest semi-axis (px)."""
        return float(1.0 / np.sqrt(np.linalg.eigvalsh(self.Qm)[0]))


def _inscribed(n: int) -> float:
    """Second moment per area of an ellipse over that of the n-gon inscribed in it at
    equal steps of its parameter: ``3 / (2 + cos(2 pi / n))`` (the regular
    n-gon's polar moment per area is ``(2 + cos(2 pi / n)) / 6`` of the
    circumradius squared, the circle's 1/2; affine maps keep the ratio).  The
    outline's vertices are at equal steps about the cone of rays, nearly so."""
    return 3.0 / (2.0 + np.cos(2.0 * np.pi / n))


def moment_ellipse(poly) -> tuple[np.ndarray, Ellipse]:
    """Centroid and the ellipse with the same area and second moments as a polygon.

    An ellipse ``d^T Q d <= 1`` has second central moments ``Q^-1 / 4`` per
    unit area, so ``Q = (4 M)^-1`` with ``M`` the polygon's, scaled up by
    :func:`_inscribed` for a polygon inscribed in the outline.

    Parameters
    ----------
    poly : ndarray, shape (n, 2)
        Vertices in order (px).

    Returns
    -------
    centroid : ndarray, shape (2,)
    ellipse : Ellipse
    """
    p = np.asarray(poly, float)
    c0 = p.mean(axis=0)
    p = p - c0  # moments about a near point: no cancellation
    q = np.roll(p, -1, axis=0)
    cr = p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]
    A = cr.sum() / 2.0
    cx = ((p[:, 0] + q[:, 0]) * cr).sum() / (6.0 * A)
    cy = ((p[:, 1] + q[:, 1]) * cr).sum() / (6.0 * A)
    # Shoelace second moments about the origin.
    Ixx = ((p[:, 0] ** 2 + p[:, 0] * q[:, 0] + q[:, 0] ** 2) * cr).sum() / 12.0
    Iyy = ((p[:, 1] ** 2 + p[:, 1] * q[:, 1] + q[:, 1] ** 2) * cr).sum() / 12.0
    Ixy = ((p[:, 0] * q[:, 1] + 2 * p[:, 0] * p[:, 1] + 2 * q[:, 0] * q[:, 1] + q[:, 0] * p[:, 1])
           * cr).sum() / 24.0
    M = np.array([[Ixx / A - cx * cx, Ixy / A - cx * cy], [Ixy / A - cx * cy, Iyy / A - cy * cy]])
    Q = np.linalg.inv(4.0 * M * _inscribed(len(p)))
    Q = 0.5 * (Q + Q.T)
    return c0 + np.array([cx, cy]), Ellipse(tuple(map(tuple, Q)))


def local_outline(camera, uv, R: float, r_disc: float | None = None):
    """The ball's outline near pixel ``uv`` as an ellipse, or None for a disc.

    Parameters
    ----------
    camera : Camera
    uv : array_like, shape (2,)
        Where the ball's image is (px, to a pixel or so: the shape varies by
        ~1e-3 px per px of position on a 1.5 m, 15 degree view).
    R : float
        Ball radius (m).
    r_disc : float, optional
        The tracker's disc radius (px): when the outline is that disc within
        ``CIRCLE_TOL_PX``, None is returned and the disc is fitted.

    Returns
    -------
    Ellipse or None
    """
    xy = camera.to_table(np.asarray(uv, float).reshape(1, 2))
    if not np.all(np.isfinite(xy)):
        return None
    poly = camera.ball_outline(xy, R, OUTLINE_VERTICES)[0]
    if not np.all(np.isfinite(poly)):
        return None
    _, ell = moment_ellipse(poly)
    if r_disc is not None:
        Q = ell.Qm
        # Q = I / r^2 within tolerance: semi-axes within CIRCLE_TOL_PX of r.
        dev = np.abs(np.linalg.eigvalsh(Q) ** -0.5 - r_disc).max()
        if dev < CIRCLE_TOL_PX:
            return None
    return ell


def _slices(Q):
    """The ellipse's chords along both axes.

    Vertical chords: at ``x`` (relative to the centre) ``y`` runs over
    ``n x -/+ hv s``, ``s = sqrt(1 - (x / wv)^2)``, for ``|x| <= wv``;
    horizontal chords: at ``y``, ``x`` runs over ``m y -/+ wh sqrt(1 - (y / hh)^2)``.
    """
    A, B, C = Q[0, 0], Q[0, 1], Q[1, 1]
    n, hv, wv = -B / C, 1.0 / np.sqrt(C), 1.0 / np.sqrt(A - B * B / C)
    m, wh, hh = -B / A, 1.0 / np.sqrt(A), 1.0 / np.sqrt(C - B * B / A)
    return n, hv, wv, m, wh, hh


def ellipse_corner_area(x, y, Q):
    """Area of the ellipse ``d^T Q d <= 1`` with ``d_x <= x`` and ``d_y <= y``.

    Vectorised over ``x`` and ``y`` (broadcast); exact.  Over vertical
    slices, the part of the chord ``[yb, yt]`` below ``y`` is
    ``2 hv s - (yt - y)^+ + (yb - y)^+``; the first term integrates to a
    circular segment, the second over the interval where the upper arc is
    above ``y`` and the third, written as ``(yb - y) + (y - yb)^+``, over
    where the lower arc is below it: each interval's ends are where the line
    meets that arc, or the ellipse's left and right ends.
    """
    n, hv, wv, m, wh, hh = _slices(np.asarray(Q, float))
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    xc = np.clip(x, -wv, wv)

    def seg(z):  # hv int_{-wv}^{z} s(X) dX, less its constant (cancels in differences)
        xi = np.clip(z / wv, -1.0, 1.0)
        return 0.5 * hv * wv * (xi * np.sqrt(np.maximum(1.0 - xi * xi, 0.0)) + np.arcsin(xi))

    def poly(z):  # the rest of the primitive of n X + k hv s(X) - y
        return (0.5 * n * z - y) * z

    # The square roots and arcsines are taken on x alone or on y alone (each
    # varies along one axis of a patch), never on their broadcast: a clipped
    # argument's segment is the segment of whichever end it was clipped to.
    Sx = seg(xc)
    T1 = 2.0 * Sx + 0.5 * np.pi * hv * wv
    # Where the line at height y meets the ellipse (horizontal chord ends).
    eta = np.clip(y / hh, -1.0, 1.0)
    half = wh * np.sqrt(np.maximum(1.0 - eta * eta, 0.0))
    xl, xr = m * y - half, m * y + half
    above, below = y >= hh, y <= -hh
    out = np.full(np.shape(y), wv)

    def interval(on_arc_l, on_arc_r, full, empty):
        a = np.where(full, -wv, np.where(empty, out, np.where(on_arc_l, xl, -wv)))
        b = np.where(full, wv, np.where(empty, out, np.where(on_arc_r, xr, wv)))
        return a, np.maximum(a, b)

    def part(a, b, k):  # int_a^{clip(xc, a, b)} (n X + k hv s(X) - y) dX
        u = np.clip(xc, a, b)
        Sa, Sb = seg(a), seg(b)
        Su = np.where(xc <= a, Sa, np.where(xc >= b, Sb, Sx))
        return poly(u) - poly(a) + k * (Su - Sa)

    # Upper arc above y on [a2, b2]: ends at the roots on the upper arc (y >= n x).
    a2, b2 = interval(y >= n * xl, y >= n * xr, below, above)
    # Lower arc below y on [a3, b3]: ends at the roots on the lower arc (y <= n x).
    a3, b3 = interval(y <= n * xl, y <= n * xr, above, below)
    lower = poly(xc) - poly(-wv) - (Sx - seg(np.full(np.shape(y), -wv)))
    return T1 - part(a2, b2, 1.0) + lower - part(a3, b3, -1.0)


def ellipse_with_gradient(cu, cv, ell: Ellipse, u0: int, v0: int, w: int, h: int):
    """Exact pixel coverage of an ellipse and its derivatives w.r.t. the centre.

    The counterpart of :func:`cuespin.track.model.disc_with_gradient` (same
    arguments and returns, ``ell`` in place of the radius): coverage is the
    second difference of :func:`ellipse_corner_area` over the pixel corners,
    and moving the ellipse right gains its chord on a pixel's left edge and
    loses the one on its right edge.
    """
    Q = ell.Qm
    n, hv, wv, m, wh, hh = _slices(Q)
    cu = np.asarray(cu, float)[..., None, None]
    cv = np.asarray(cv, float)[..., None, None]
    xe = np.arange(u0, u0 + w + 1) - 0.5 - cu                       # (..., 1, w+1)
    ye = np.swapaxes(np.arange(v0, v0 + h + 1) - 0.5 - cv, -1, -2)  # (..., h+1, 1)
    G = ellipse_corner_area(xe, ye, Q)
    cov = G[..., 1:, 1:] - G[..., 1:, :-1] - G[..., :-1, 1:] + G[..., :-1, :-1]
    # Vertical chords on column edges, within each row.
    sv = hv * np.sqrt(np.maximum(1.0 - (xe / wv) ** 2, 0.0))
    yb, yt = n * xe - sv, n * xe + sv                                 # (..., 1, w+1)
    vert = np.maximum(np.minimum(ye[..., 1:, :], yt) - np.maximum(ye[..., :-1, :], yb), 0.0)
    sh = wh * np.sqrt(np.maximum(1.0 - (ye / hh) ** 2, 0.0))
    xl, xr = m * ye - sh, m * ye + sh                                 # (..., h+1, 1)
    horz = np.maximum(np.minimum(xe[..., :, 1:], xr) - np.maximum(xe[..., :, :-1], xl), 0.0)
    d_du = vert[..., :, :-1] - vert[..., :, 1:]
    d_dv = horz[..., :-1, :] - horz[..., 1:, :]
    return cov, d_du, d_dv


def is_similarity(camera, rtol: float = 1e-9) -> bool:
    """Whether the ball's image is the same disc everywhere: a camera without
    lens or pose whose homography is a similarity (rotation, scale, shift,
    maybe a reflection), such as the conventions' top-down default."""
    if camera is None:
        return True
    if camera.has_lens or camera.is_pinhole:
        return False
    H = np.asarray(camera.homography, float)
    H = H / H[2, 2]
    if np.abs(H[2, :2]).max() > rtol * np.abs(H[:2, :2]).max():
        return False  # projective: the scale varies over the image
    A = H[:2, :2]
    AtA = A.T @ A
    s2 = 0.5 * np.trace(AtA)
    return bool(np.abs(AtA - s2 * np.eye(2)).max() <= rtol * s2)


# The outline is reused while the ball stays within this distance (px) of
# where it was computed (a ball at rest), and the fit is redone with the
# outline at its own centre when that lies further from where the outline
# was computed (track.tracker).  The shape changes by up to 0.3% per px
# (1.5 m, 15 degrees, k1 +0.25, near the camera), and a size error matters
# though the model is symmetric: on a ball cut by its patch's edge, and in
# the residual it leaves on every edge pixel (2% of Q put a 17-px ball
# 0.15 px off on a cut patch and doubled its residual RMS; measured).
OUTLINE_REUSE_PX = 0.25
OUTLINE_REFIT_PX = 0.5


class OutlineCache:
    """:func:`local_outline` along a track, reused while the ball stays put.

    Parameters
    ----------
    camera : Camera
    R : float
        Ball radius (m).
    r_disc : float
        The tracker's disc radius (px).
    """

    def __init__(self, camera, R: float, r_disc: float):
        self.camera, self.R, self.r_disc = camera, float(R), float(r_disc)
        self.at = None
        self._ell = None

    def __call__(self, uv):
        uv = np.asarray(uv, float)
        if self.at is None or np.hypot(*(uv - self.at)) > OUTLINE_REUSE_PX:
            self.at = uv.copy()
            self._ell = local_outline(self.camera, uv, self.R, self.r_disc)
        return self._ell
