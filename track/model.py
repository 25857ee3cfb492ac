"""Sub-pixel ball location on a background-subtracted patch (pure functions).

Two refinements:

* ``fit_disc``: least squares of the exact pixel-area model of a disc (the
  renderer's own ``disc_coverage``), optionally smeared along a straight
  blur segment, with analytic derivatives.  With Gaussian noise this is the
  maximum-likelihood estimate, and it reaches the Cramer-Rao bound.
* ``moments``: grey-weighted centroid in a circular window, iterated.  About
  2-3x the bound, kept for comparison and as the fit's starting point.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from cuespin.render.draw import quadrant_area
from cuespin.track.outline import Ellipse, _slices, ellipse_with_gradient

# Gauss-Newton's iteration cap: a shaded ball at rest needs 18-48
# (realistic seed 0 shot 6, FFV1: at 24, 11 of 97 frames lost; at 64, none).
MAX_ITER = 64
# Where the look departs from the model (chroma subsampled at half
# resolution, a lossy codec's ringing, a shaded ball) the residuals are
# large and Gauss-Newton converges only linearly: each step 0.4 of the one
# before, all in one direction (MJPG colour video: 6-7 iterations a frame),
# or cycling between two centres 0.002-0.01 px apart (yuv420p FFV1).  Both
# are a geometric sequence of steps, whose sum the last two steps give
# (Aitken): when two successive steps are nearly parallel (cosine beyond
# AITKEN_COS) with ratio rho, the step is scaled by 1 / (1 - rho), rho
# clipped to AITKEN_RHO (a cycle, rho near -1, gets the step halved).
AITKEN_COS = 0.8
AITKEN_RHO = (-0.9, 0.8)
# After this many steps every step is halved as well (a last resort).
DAMP_AFTER = 12
# Gauss-Newton also stops when the centre moves less than this fraction of
# its own standard error (pooled residual, the normal equations): with the
# iteration converging at rate <= 0.5 what is left is at most as large,
# adding at most 1% to the centre's variance.
STEP_TOL_SE = 0.1
# Block size (px) of the cluster-robust sandwich used with the shaded look.
CLUSTER_PX = 3
# The same with the lit sphere's look (0: HC1, per pixel).  See SphereLook.
SPHERE_CLUSTER_PX = 0
# The sphere's normal's z below this is taken as this in its derivative
# (d nz / dX = -X / nz grows without bound at the rim, where a pixel's
# centre is rarely that close; the value itself is exact).
SPHERE_NZ_MIN = 0.05
# A fit still stepping after MAX_ITER is kept if its last step is below this
# fraction of the centre's standard error (it adds at most 4% to its variance).
NO_CONVERGENCE_SE = 0.2
# Gauss-Newton stops when the centre moves less than this (px).  It
# converges quadratically from the moments start (~0.02 px off), so the
# error left after a step this small is ~1e-6 px, far below any bound.
STEP_TOL_PX = 1e-3
# Blur nodes per pixel of blur length: the fit's model of a streak.
BLUR_NODES_PER_PX = 1.0
MAX_BLUR_NODES = 24
# The kernel's settings (cuespin.track.kernel's ``consts``, in its order)
# and the reasons its outcomes 1-4 stand for.
_CONSTS = np.array([MAX_ITER, STEP_TOL_PX, STEP_TOL_SE, AITKEN_COS, AITKEN_RHO[0], AITKEN_RHO[1], DAMP_AFTER,
                    NO_CONVERGENCE_SE, CLUSTER_PX, BLUR_NODES_PER_PX, MAX_BLUR_NODES, SPHERE_CLUSTER_PX],
                   dtype=np.float64)
FIT_REASONS = ("", "singular normal equations", "diverged", f"no convergence in {MAX_ITER} iterations",
               "centre left the patch")


def _chords(edges, lo, hi, r):
    """Length of the disc's chord on the lines ``x = edges`` within ``[lo, hi]``.

    ``edges`` has shape (1, n) or (n, 1) and ``lo``, ``hi`` broadcast against
    it; coordinates are relative to the centre (px).
    """
    s = np.sqrt(np.maximum(r * r - edges * edges, 0.0))
    return np.maximum(np.minimum(hi, s) - np.maximum(lo, -s), 0.0)


def disc_with_gradient(cu, cv, r: float, u0: int, v0: int, w: int, h: int):
    """Exact pixel coverage of a disc and its derivatives w.r.t. the centre.

    Parameters
    ----------
    cu, cv : float or ndarray, shape (K,)
        Centre (px); K centres give K patches at once.
    r : float
        Radius (px).
    u0, v0 : int
        Column and row of the patch's top-left pixel.
    w, h : int
        Patch size (px).

    Returns
    -------
    cov, d_du, d_dv : ndarray, shape (h, w) or (K, h, w)
        Covered area per pixel and its derivatives (per px of centre shift):
        moving the disc right gains the chord on a pixel's left edge and
        loses the one on its right edge.
    """
    cu = np.asarray(cu, float)[..., None, None]
    cv = np.asarray(cv, float)[..., None, None]
    xe = np.arange(u0, u0 + w + 1) - 0.5 - cu  # column edges, relative: (..., 1, w+1)
    ye = np.swapaxes(np.arange(v0, v0 + h + 1) - 0.5 - cv, -1, -2)  # row edges: (..., h+1, 1)
    G = quadrant_area(xe, ye, r)
    cov = G[..., 1:, 1:] - G[..., 1:, :-1] - G[..., :-1, 1:] + G[..., :-1, :-1]
    vert = _chords(xe, ye[..., :-1, :], ye[..., 1:, :], r)                       # (..., h, w+1)
    horz = _chords(ye, xe[..., :, :-1], xe[..., :, 1:], r)                       # (..., h+1, w)
    d_du = vert[..., :, :-1] - vert[..., :, 1:]
    d_dv = horz[..., :-1, :] - horz[..., 1:, :]
    return cov, d_du, d_dv


def coverage_with_gradient(cu, cv, r, u0, v0, w, h, outline=None):
    """:func:`disc_with_gradient`, or the ellipse's
    (:func:`cuespin.track.outline.ellipse_with_gradient`) when ``outline`` is given."""
    if outline is None:
        return disc_with_gradient(cu, cv, r, u0, v0, w, h)
    return ellipse_with_gradient(cu, cv, outline, u0, v0, w, h)


@dataclass(frozen=True)
class SphereLook:
    """The ball's look as a lit sphere seen from above, fixed for a video.

    A matte or glossy ball under one light has, at the image point ``X``
    (ball radii from its centre) with the sphere's normal ``n = (X, Y,
    sqrt(1 - |X|^2))`` (clamped to the rim past it), the level ``G + a
    max(n.L, 0) + s max(n.H, 0)^p + q (|X|^2 - 1/2)``: an ambient level,
    Lambert's diffuse term with its terminator, Blinn's highlight (``H`` the
    half vector between ``L`` and the view, straight up) and a rim term for
    what the two leave (a lens's blur).  In a combination of colour channels
    the coefficients stay linear (each channel's albedo scales ``a``, the
    light's colour ``s``); only the geometry, ``L`` and ``p``, is nonlinear,
    and as the light is fixed to the table it is the same in every frame:
    learnt once (:func:`cuespin.track.sphere.learn_sphere`), each frame then
    fits its centre, blur and the three coefficients.  Unlike a free look
    (a template, or the quadratic look's lit side ``gu X + gv Y``, which
    trades against the centre) the basis is tied to the silhouette: the
    terminator and the highlight sit where the geometry puts them relative
    to the rim, so they cannot absorb a shift of the centre.

    The lens's blur, a Gaussian PSF of ``psf`` px, is the same in every
    frame too and learnt with the light: the model's pixels (the exact
    coverage times the look) are then convolved with it, as the optics do
    before the sensor (:func:`cuespin.track.kernel.psf_blur`).  A sharp
    model fitted to a blurred ball lost half the information
    (benchmarks/track.py realistic seed 0 shot 9, PSF 0.86 px: RMSE 2.1x
    the bound) or was biased (shot 4: 0.2 px along the motion).

    Attributes
    ----------
    azimuth : float
        Direction of the light in the image (rad, from +u towards +v).
    elevation : float
        Its angle above the cloth (rad; pi/2 overhead).
    shininess : float
        Blinn's exponent ``p``.
    psf : float
        The lens's PSF, a Gaussian's sigma (px); 0: none.
    """

    azimuth: float
    elevation: float
    shininess: float
    psf: float = 0.0

    def geometry(self) -> np.ndarray:
        """``(L, H, p, nz_min, psf)``, shape (9,): what the kernel reads after
        the three coefficients (``L``, ``H`` unit vectors in image axes, z
        up; ``psf`` at the look's index ``kernel.PSF_AT``)."""
        ce = np.cos(self.elevation)
        L = np.array([ce * np.cos(self.azimuth), ce * np.sin(self.azimuth), np.sin(self.elevation)])
        H = L + np.array([0.0, 0.0, 1.0])
        return np.r_[L, H / np.linalg.norm(H), float(self.shininess), SPHERE_NZ_MIN, float(self.psf)]


def sphere_basis(X, Y, g):
    """The lit sphere's two basis functions and their derivatives (numpy).

    Parameters
    ----------
    X, Y : ndarray
        Points, in ball radii from the centre (broadcast).
    g : array_like, shape (12,)
        The look (``g[3:12]`` = :meth:`SphereLook.geometry`; its PSF,
        ``g[11]``, acts on the model's pixels, not here).

    Returns
    -------
    D, S, dDx, dDy, dSx, dSy : ndarray
        ``max(n.L, 0)``, ``max(n.H, 0)^p`` and their derivatives in ``X``
        and ``Y``; past the rim ``n`` is the rim's normal (the renderer's
        clamp), whose derivatives are those of ``(X, Y, 0) / |X|``.
    """
    g = np.asarray(g, float)
    X, Y = np.broadcast_arrays(np.asarray(X, float), np.asarray(Y, float))
    rho2 = X * X + Y * Y
    out = rho2 > 1.0
    s = 1.0 / np.sqrt(np.where(out, rho2, 1.0))
    s3 = s * s * s
    nz = np.sqrt(np.maximum(1.0 - rho2, 0.0))
    den = np.maximum(nz, g[10])
    nx, ny = np.where(out, X * s, X), np.where(out, Y * s, Y)
    nxx, nyy = np.where(out, s - X * X * s3, 1.0), np.where(out, s - Y * Y * s3, 1.0)
    nxy = np.where(out, -X * Y * s3, 0.0)
    nzx, nzy = np.where(out, 0.0, -X / den), np.where(out, 0.0, -Y / den)

    def term(V):
        nv = nx * V[0] + ny * V[1] + nz * V[2]
        return nv, nxx * V[0] + nxy * V[1] + nzx * V[2], nxy * V[0] + nyy * V[1] + nzy * V[2]

    nl, lx, ly = term(g[3:6])
    lit = nl > 0.0
    D, dDx, dDy = np.where(lit, nl, 0.0), np.where(lit, lx, 0.0), np.where(lit, ly, 0.0)
    nh, hx, hy = term(g[6:9])
    p = g[9]
    on = nh > 0.0
    nhp = np.where(on, nh, 1.0)
    S = np.where(on, nhp ** p, 0.0)
    f = np.where(on, p * S / nhp, 0.0)
    return D, S, dDx, dDy, f * hx, f * hy


def look_value(X, Y, shade):
    """The look less its level at ``(X, Y)`` (ball radii): value, its
    derivatives in ``X`` and ``Y``, and the three basis functions
    ``shade[:3]`` multiplies (:func:`cuespin.track.kernel.look_at`'s numpy
    form): the quadratic look (``shade`` of 3) or the lit sphere's (12)."""
    Q = X * X + Y * Y - 0.5
    if len(shade) < 11:
        gu, gv, q = shade[:3]
        return gu * X + gv * Y + q * Q, gu + 2 * q * X, gv + 2 * q * Y, X, Y, Q
    a, s, q = shade[:3]
    D, S, dDx, dDy, dSx, dSy = sphere_basis(X, Y, shade)
    return a * D + s * S + q * Q, a * dDx + s * dSx + 2 * q * X, a * dDy + s * dSy + 2 * q * Y, D, S, Q


def blur_nodes(blur_px: float) -> np.ndarray:
    """Fractions of the exposure, centred on 0, at which the streak is sampled."""
    if blur_px < 0.25:
        return np.zeros(1)
    K = int(min(MAX_BLUR_NODES, max(2, np.ceil(blur_px * BLUR_NODES_PER_PX))))
    return (np.arange(K) + 0.5) / K - 0.5


def streak_model(c, b, G, felt, r, u0, v0, taus, shade=None, blur_cols=True, outline=None):
    """Frame minus felt for a ball of grey ``G`` smeared from ``c - b/2`` to ``c + b/2``.

    The ball hides the felt under it, so the model is ``(G - felt) * cov``
    with ``cov`` the exposure-averaged coverage.  Returns the model patch
    and its Jacobian, shape (h*w, 5), with columns
    ``d/dcu, d/dcv, d/dbu, d/dbv, d/dG``.

    ``shade = (gu, gv, q)``, when given, is the ball's look: its level at a
    point ``X`` (px, from the ball's centre) is
    ``G + (gu X_u + gv X_v) / r + q (|X|^2 / r^2 - 1/2)``, a lit side and a
    rim darker or lighter than the middle (shading, a highlight's mean),
    taken at each pixel's centre within the exact coverage.  Three more
    Jacobian columns then follow, ``d/dgu, d/dgv, d/dq``.  ``shade`` of 12,
    ``(a, s, q)`` and a :class:`SphereLook`'s geometry, is the lit sphere's
    look ``G + a max(n.L, 0) + s max(n.H, 0)^p + q (|X|^2 / r^2 - 1/2)``
    instead, its columns ``d/da, d/ds, d/dq``, the model and every column
    then convolved with its PSF when it has one (``shade[11]`` > 0).
    Either way the centre's columns move the look with the ball.

    ``blur_cols`` False leaves the blur's columns ``d/dbu, d/dbv`` zero (a
    fit that holds the blur fixed never reads them: two tensor products
    per evaluation saved).

    ``outline``, when given (an :class:`~cuespin.track.outline.Ellipse`),
    is the ball's image in place of the disc of radius ``r`` (the look's
    ``X / r`` still uses ``r``, the ball's scale).
    """
    m, JT = _model_rows(c, b, G, felt, r, u0, v0, taus, shade, blur_cols, outline)
    if not blur_cols:  # the blur's rows were left out: zero columns in their place
        JT = np.insert(JT, 2, 0.0, axis=0)
        JT = np.insert(JT, 2, 0.0, axis=0)
    return m, JT.T


def _model_rows(c, b, G, felt, r, u0, v0, taus, shade=None, blur_rows=True, outline=None):
    """:func:`streak_model` with its Jacobian transposed, shape (k, h*w), and
    the blur's two rows left out when ``blur_rows`` is False (k = 3, or 6
    with ``shade``).  The fit's working form: contiguous rows make ``J^T J``
    one product, and the columns a fit does not read are never built.
    Compiled (:func:`cuespin.track.kernel.model_rows`); the numpy form is
    :func:`cuespin.track.reference.model_rows`.
    """
    felt = np.ascontiguousarray(felt, dtype=np.float64)
    h, w = felt.shape
    k = (5 if blur_rows else 3) + (3 if shade is not None else 0)
    m, JT = np.empty(h * w), np.empty((k, h * w))
    kind, geo = _geometry(r, outline)
    kernel().model_rows(float(c[0]), float(c[1]), float(b[0]), float(b[1]), float(G), felt, float(r), kind, geo,
                        int(u0), int(v0), np.ascontiguousarray(taus, dtype=np.float64),
                        _NO_SHADE if shade is None else np.ascontiguousarray(shade, dtype=np.float64),
                        shade is not None,
                        bool(blur_rows), m, JT)
    return m.reshape(h, w), JT


_NO_SHADE = np.zeros(3)
_NO_GEO = np.zeros(0)
_KERNEL = None


def kernel():
    """The compiled kernel, :mod:`cuespin.track.kernel`, imported on first
    use: importing numba costs ~0.5 s, which only a fit should pay."""
    global _KERNEL
    if _KERNEL is None:
        from cuespin.track import kernel as compiled
        _KERNEL = compiled
    return _KERNEL


def warm_up() -> None:
    """Load the compiled fit (after an install, compile it: once) with one
    small call of each kernel the tracker uses, so that the first frame's
    fit need not wait for it.  A failure is left for that fit to raise."""
    try:
        felt = np.full((9, 9), 90.0)
        fit_disc(felt + 1.0, felt, 0, 0, (4.0, 4.0), 3.0, 200.0)
        _model_rows((4.0, 4.0), (0.0, 0.0), 1.0, felt, 3.0, 0, 0, np.zeros(1))
    except Exception:  # the tracker's own call reports it
        pass


def _geometry(r: float, outline):
    """The ball's image for the kernel: (DISC, [r]) or (ELLIPSE, its chords)."""
    if outline is None:
        return 0, np.array([float(r)])
    return 1, np.array(_slices(outline.Qm), dtype=np.float64)


@dataclass(frozen=True)
class DiscFit:
    """Result of :func:`fit_disc`; falsy when the fit failed.

    Attributes
    ----------
    ok : bool
        Converged to a ball-like solution.
    reason : str
        Why not, when ``ok`` is False.
    c : ndarray, shape (2,)
        Centre of the (blurred) ball's image (px): the exposure's middle.
    b : ndarray, shape (2,)
        Blur vector over the exposure (px); zeros when not fitted.
    G : float
        The ball's grey level.
    stderr : ndarray, shape (2,)
        Standard errors of ``c`` from the residual noise (px).
    cov : ndarray, shape (2, 2)
        Covariance of ``c`` (px^2), the sandwich's; ``stderr`` is the root of
        its diagonal.
    rms : float
        Residual RMS (grey levels).
    n_iter : int
        Gauss-Newton iterations taken.
    shade : ndarray or None
        The look's fitted coefficients when it was fitted: shape (3,) for
        the quadratic look, (12,) for a :class:`SphereLook` (its three
        coefficients, then its geometry): either passes back to
        :func:`streak_model` and :func:`refit_shift` as their ``shade``.
    """

    ok: bool
    reason: str
    c: np.ndarray
    b: np.ndarray
    G: float
    stderr: np.ndarray
    rms: float
    n_iter: int
    cov: np.ndarray = None
    shade: np.ndarray | None = None

    def __bool__(self):
        return self.ok

    @property
    def stated(self) -> bool:
        """Whether the fit states its centre's error: a finite, positive
        definite ``cov``.  No stated error is no measurement: a zero or
        indefinite covariance would weigh the frame infinitely or
        negatively downstream (a lit sphere's refit of seed 22 realistic
        shot 16, FFV1, gave 11 frames variances of -49 to 7e10 px^2)."""
        c = self.cov
        return c is not None and bool(np.all(np.isfinite(c)) and c[0, 0] > 0 and c[1, 1] > 0
                                      and c[0, 0] * c[1, 1] - c[0, 1] * c[1, 0] > 0)


def fit_disc(frame: np.ndarray, felt: np.ndarray, u0: int, v0: int, c0, r: float, G0: float,
             b0=(0.0, 0.0), fit_blur: bool = False, shade: bool = False, valid=None,
             outline=None, block=1, jackknife: bool = True) -> DiscFit:
    """Least-squares fit of the exact disc (or streak) model to a patch.

    Parameters
    ----------
    frame : ndarray, shape (h, w)
        The frame's patch (grey levels).
    felt : ndarray, shape (h, w)
        The background model's patch (grey levels).
    u0, v0 : int
        Column and row of the patch's top-left pixel in the frame.
    c0 : array_like, shape (2,)
        Starting centre (px).
    r : float
        Ball radius (px), known from ``physics.R`` and the homography.
    G0 : float
        Starting grey level of the ball.
    b0 : array_like, shape (2,)
        Blur vector over the exposure (px): the starting value, or the fixed
        value when ``fit_blur`` is False.
    fit_blur : bool
        Estimate the blur vector too.
    shade : bool or SphereLook
        Fit the ball's look too (:func:`streak_model`'s ``shade``: lit
        side and rim, three linear nuisances), for a shaded ball whose
        uniform-disc fit is pulled towards its lit side; a
        :class:`SphereLook`: the lit sphere's look of that geometry (its
        three coefficients fitted).
    valid : ndarray of bool, shape (h, w), optional
        Pixels the fit may use (others, e.g. the cue's, are left out).
    outline : Ellipse, optional
        The ball's local outline under perspective
        (:func:`cuespin.track.outline.local_outline`), its shape fixed and
        its centre fitted; ``c`` is then that ellipse's centre.  None: the
        disc of radius ``r``.
    block : int or (int, int)
        The patch holds the means of ``block`` x ``block`` pixel blocks
        (a pair: width x height, :func:`block_sides`), aligned to multiples
        of their sides in the frame, each repeated over its block: a
        subsampled video's colour as its decoder hands it back (4:2:0: 2;
        4:2:2: (2, 1); 4:1:1: (4, 1)), seen through a projection blind to
        luma.  The model is then averaged over the same blocks
        (:func:`block_patch`); 1: pixels.
    jackknife : bool
        With ``block`` > 1, the covariance from the blocks' jackknife
        (:func:`_jackknife_cov`); False keeps the fit's own sandwich, for
        callers that read only the fit's residual, centre or look (its cost
        is ~0.3-0.9 ms a fit).

    Returns
    -------
    DiscFit
        Never raises for bad data; ``ok`` False with a reason instead.
    """
    if block_area(block) > 1:
        return _fit_blocks(block, frame, felt, u0, v0, c0, r, G0, b0, fit_blur, shade, valid, outline,
                           jackknife=jackknife)
    felt = np.ascontiguousarray(felt, dtype=np.float64)
    h, w = felt.shape
    y = (np.asarray(frame, dtype=np.float64) - felt).ravel()
    use = np.ones(h * w) if valid is None else np.asarray(valid, float).ravel()
    c = np.array(c0, dtype=float)
    b = np.array(b0, dtype=float)
    if isinstance(shade, SphereLook) and outline is not None:
        # The lit sphere's shading is scaled by the ball's image, whose size
        # under perspective is the outline's, not the table-wide ``r``: at
        # an outline 1.1x and 1.3x r the centre was 5.3 and 4.0 of its
        # errors off, at the outline's own radius 0.007 px (review).
        r = outline.radius
    kind, geo = _geometry(r, outline)
    # Gauss-Newton with Aitken's acceleration, then the sandwich, compiled
    # (cuespin.track.kernel.fit; the numpy form, with the reasons for each
    # rule, is cuespin.track.reference.fit_disc).
    look_geo = shade.geometry() if isinstance(shade, SphereLook) else _NO_GEO
    outcome, G, look, it, se, cov, rms = kernel().fit(
        y, felt, use, valid is not None, c, b, float(G0), float(r), kind, geo, int(u0), int(v0), bool(shade),
        look_geo, bool(fit_blur), _CONSTS)
    if outcome == kernel().FIT_NO_CONVERGENCE and isinstance(shade, SphereLook):
        g = _kinked_minimum(y, felt, use, valid is not None, c, b, r, u0, v0, shade, fit_blur, outline, it)
        if g:
            return g
    if outcome:
        return _failed(FIT_REASONS[outcome], c, b, G, it)
    return DiscFit(True, "", c, b, G, se, rms, it, cov, look if shade else None)


# The lit sphere's look is taken at each pixel's centre, as the renderer
# draws it (FrameRenderer._ball_windows), and it is not smooth there: the
# normal's ``nz = sqrt(1 - rho^2)`` has an infinite slope at the rim and
# ``max(n.L, 0)`` a kink at the terminator, so each pixel centre that
# crosses either as the centre moves puts a kink in the residual sum.  On
# a strongly shaded ball (realistic seed 0 shot 18: ambient 0.25, light
# at 0.92 rad, r 12.2 px) the sum's second difference over centre steps of
# 0.005 px jumps from ~20 to -150..+190 every ~0.02 px, and Gauss-Newton,
# whose step is the local quadratic's, cycles within ~0.03 px around the
# minimum for 400 iterations (92 of 374 refits of marked frames there,
# docs/measurements.md, branch marks7).  Then the centre (and the blur when
# fitted) is found by a compass search of the residual sum with the four
# linear coefficients (level, diffuse, highlight, rim) solved at each
# point: first step KINK_STEP_PX (the cycle's size), halved when no move
# helps, down to KINK_MIN_STEP_PX (far below the bound: 0.002 px there).
KINK_STEP_PX = 0.02
KINK_MIN_STEP_PX = 1e-4
# The search refines where Gauss-Newton cycled; a minimum farther than this
# from there is not the one it circled (a fit running off): no fit.
# Measured on the 172 refits that cycled (blur5's dump, realistic seed 0
# shot 18; /tmp/marks9/kink.py with no limit): the search moved the centre
# 0.009 px (median), 0.029 (90%), 0.085 at most from where the cycle
# stopped; 0.25 is three times the largest.
KINK_MAX_MOVE_PX = 0.25


def _kinked_minimum(y, felt, use, has_valid, c, b, r, u0, v0, look: SphereLook, fit_blur, outline, it):
    """The lit sphere's least-squares fit where Gauss-Newton cycled
    (:data:`KINK_STEP_PX`'s comment): a :class:`DiscFit` from a compass
    search started at ``c``, ``b`` (where the cycle stopped), its
    covariance the kernel's sandwich (HC1) at the minimum found; a falsy
    fit when the search ran off or the normal equations are singular."""
    h, w = felt.shape
    sel = np.asarray(use, bool) if has_valid else np.ones(h * w, bool)
    geo = look.geometry()
    zero_look = np.r_[0.0, 0.0, 0.0, geo]
    n_free = 4 if fit_blur else 2

    def profile(x):
        cb = (x[:2], x[2:4] if fit_blur else b)
        m, JT = _model_rows(cb[0], cb[1], 0.0, felt, r, u0, v0, blur_nodes(float(np.hypot(*cb[1]))), zero_look,
                            False, outline)
        L = JT[2:6, sel].T  # d/dG, d/da, d/ds, d/dq: the model is linear in them
        e = y[sel] - m.ravel()[sel]
        theta, *_ = np.linalg.lstsq(L, e, rcond=None)
        res = e - L @ theta
        return float(res @ res), theta

    x0 = np.r_[c, b] if fit_blur else np.array(c, float)
    x, (best, theta) = x0.copy(), profile(x0)
    step = KINK_STEP_PX
    while step >= KINK_MIN_STEP_PX:
        moved = False
        for k in range(n_free):
            for sign in (1.0, -1.0):
                t = x.copy()
                t[k] += sign * step
                v, th = profile(t)
                if v < best:
                    x, best, theta, moved = t, v, th, True
                    break
        if not moved:
            step /= 2
        if np.hypot(*(x[:2] - x0[:2])) > KINK_MAX_MOVE_PX:
            return _failed(FIT_REASONS[3], x[:2], b, float("nan"), it)
    cc, bb = x[:2].copy(), (x[2:4].copy() if fit_blur else np.array(b, float))
    if not (u0 - 0.5 <= cc[0] <= u0 + w - 0.5 and v0 - 0.5 <= cc[1] <= v0 + h - 0.5):
        return _failed(FIT_REASONS[4], cc, bb, float(theta[0]), it)
    # The kernel's sandwich at the minimum (kernel.fit: HC1 with the lit
    # sphere, SPHERE_CLUSTER_PX 0), every parameter's column at once.
    shade = np.r_[theta[1:], geo]
    m, JT = _model_rows(cc, bb, float(theta[0]), felt, r, u0, v0, blur_nodes(float(np.hypot(*bb))), shade,
                        fit_blur, outline)
    J = JT[:, sel]
    res = y[sel] - m.ravel()[sel]
    dof = max(int(sel.sum()) - J.shape[0], 1)
    try:
        A = np.linalg.inv(J @ J.T)
    except np.linalg.LinAlgError:
        return _failed(FIT_REASONS[1], cc, bb, float(theta[0]), it)
    V = (A @ ((J * res * res) @ J.T) @ A)[:2, :2] * (sel.sum() / dof)
    cov = 0.5 * (V + V.T)
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return DiscFit(True, "", cc, bb, float(theta[0]), se, float(np.sqrt(best / dof)), it, cov, shade)


# A 4:2:0 video (MJPG, H.264's yuv420p) stores its colour at half
# resolution: each chroma sample is the mean of a 2 x 2 block (aligned to
# even frame coordinates), and the decoders read here (OpenCV's and PyAV's
# FFmpeg, swscale's unscaled YUV -> BGR) repeat it over the block, measured:
# a colour edge at an odd column comes back as the block's mean in both of
# its columns.  In a channel blind to luma (track.colour's white-free
# weights sum to zero, and luma enters B, G and R alike) the image is that
# chroma alone.  A model of pixels fitted to it errs with a 2 px period in
# the ball's coordinate: realistic seed 0 shot 12, MJPG (a yellow ball on
# green felt), 0.31 / 0.21 px (u / v), 71% / 61% of the error's variance.
# The block means of the disc's pixel areas are the pixel areas of the disc
# scaled by 1 / block on the blocks' grid, exactly: the fit runs there.
def block_sides(block) -> tuple[int, int]:
    """A block's ``(width, height)`` (px): ``block`` an int (a square's
    side, 4:2:0's 2) or a pair (the reader's
    :attr:`~cuespin.track.reader.VideoInfo.chroma_block`: 4:2:2's (2, 1),
    4:1:1's (4, 1))."""
    if np.ndim(block) == 0:
        return int(block), int(block)
    bx, by = block
    return int(bx), int(by)


def block_area(block) -> int:
    """Pixels a block holds (1: pixels, no blocks)."""
    bx, by = block_sides(block)
    return bx * by


def block_patch(block, u0: int, v0: int, *arrays):
    """The whole blocks of a window at ``(u0, v0)``.

    Parameters
    ----------
    block : int or (int, int)
        Block size (px; a pair: width, height, :func:`block_sides`);
        blocks are aligned to multiples of it in the frame.
    u0, v0 : int
        Column and row of the window's top-left pixel.
    *arrays : ndarray, shape (h, w), or None
        Windows: float ones are averaged over each block, bool ones (pixels
        a fit may use) kept where the whole block is; None stays None.

    Returns
    -------
    (U0, V0), list of ndarray
        The first whole block's column and row on the blocks' grid, and the
        arrays on that grid.  A pixel ``x`` of the frame is ``(x - (bx -
        1) / 2) / bx`` on it (``y``: ``by``'s).
    """
    bx, by = block_sides(block)
    h, w = next(np.shape(a) for a in arrays if a is not None)
    a, b = -u0 % bx, -v0 % by
    m, n = (w - a) // bx, (h - b) // by
    out = []
    from cuespin.track import window  # compiled: numpy's reductions cost ~0.1 ms a fit
    for x in arrays:
        if x is None:
            out.append(None)
            continue
        x = np.asarray(x)
        if x.dtype == bool:
            out.append(window.block_all(x, a, b, n, m, bx, by))
        elif x.dtype in _EXACT_BLOCK_SUMS:
            out.append(window.block_means(x, a, b, n, m, bx, by))
        else:  # float64: numpy's own order of summation
            x = x[b:b + n * by, a:a + m * bx].reshape(n, by, m, bx)
            out.append(x.mean(axis=(1, 3), dtype=np.float64))
    return ((u0 + a) // bx, (v0 + b) // by), out


# Window types whose blocks' sums are exact in float64 (any order gives
# numpy's mean bit for bit): the tracker's float32 projected windows and felt.
_EXACT_BLOCK_SUMS = (np.dtype(np.float32), np.dtype(np.uint8))


def _coarse(block, c, r: float, b, outline):
    """Centre, radius, blur and outline on the blocks' grid (:func:`block_patch`).

    A grid ``bx`` by ``by`` px a unit maps the frame by ``D = diag(1/bx,
    1/by)``: the centre and blur by it, an outline's ``Q`` to ``D^-1 Q
    D^-1``; a disc on an oblong grid (4:2:2's, 4:1:1's) is the ellipse
    ``Q = D^-1 D^-1 / r^2`` there, and the radius given back is its
    equal-area one (a square grid's ``r / b``)."""
    bx, by = block_sides(block)
    half = np.array([(bx - 1) / 2.0, (by - 1) / 2.0])
    side = np.array([bx, by], float)
    if bx == by:
        ol = None if outline is None else Ellipse(Q=tuple(map(tuple, bx * bx * outline.Qm)))
    else:
        Q = np.eye(2) / (r * r) if outline is None else outline.Qm
        ol = Ellipse(Q=tuple(map(tuple, np.outer(side, side) * Q)))
    return (np.asarray(c, float) - half) / side, r / np.sqrt(bx * by), np.asarray(b, float) / side, ol


def _fit_blocks(block, frame, felt, u0, v0, c0, r, G0, b0, fit_blur, shade, valid, outline, fit=None,
                jackknife=True) -> DiscFit:
    """:func:`fit_disc` of the block means on the blocks' grid, its centre,
    blur and covariance back in the frame's pixels.  The block means' noise
    is the chroma samples' own (one value a block), so the stated error
    counts each block once.  ``fit``: the pixels' fit (this module's
    :func:`fit_disc`, or the numpy reference's); ``jackknife`` as
    :func:`fit_disc`'s."""
    fit = fit_disc if fit is None else fit
    (U0, V0), (y, f, ok) = block_patch(block, u0, v0, frame, felt, None if valid is None else np.asarray(valid, bool))
    c, rc, b, ol = _coarse(block, c0, r, b0, outline)
    g = fit(y, f, U0, V0, c, rc, G0, b0=b, fit_blur=fit_blur, shade=shade, valid=ok, outline=ol)
    if not g:
        # From the pixels' fit, and that fit when the blocks' does not
        # converge from it either: realistic seed 0 shot 8, MJPG (a white
        # ball with a logo, blurred 6 px), 3 of 97 blocks' fits stopped
        # after MAX_ITER iterations where the pixels' converged.
        p = fit(frame, felt, u0, v0, c0, r, G0, b0=b0, fit_blur=fit_blur, shade=shade, valid=valid, outline=outline)
        if not p:
            return p
        c, _, b, _ = _coarse(block, p.c, r, p.b, outline)
        g = fit(y, f, U0, V0, c, rc, p.G, b0=b, fit_blur=fit_blur, shade=shade, valid=ok, outline=ol)
        if not g:
            # The pixels' fit counts each chroma sample bx * by times (the
            # decoder repeats it): its variance is scaled by bx * by, a
            # conservative bound (review7 measured its err/se 1.5-1.9x the
            # blocks' on the chroma test's 24 MJPG frames, 2 x 2 blocks).
            n = block_area(block)
            return replace(p, stderr=np.sqrt(n) * p.stderr, cov=n * p.cov)
    if jackknife:
        g = _jackknife_cov(g, y, f, U0, V0, rc, fit_blur, shade, ok, ol)
    side = np.array(block_sides(block), float)
    return replace(g, c=side * g.c + (side - 1) / 2.0, b=side * g.b, stderr=side * g.stderr,
                   cov=np.outer(side, side) * g.cov)


def _jackknife_cov(g: DiscFit, y, felt, U0, V0, r, fit_blur, shade, ok, outline) -> DiscFit:
    """The blocks' fit ``g`` with the jackknife's sandwich for its covariance
    (``y`` and ``felt`` the blocks' means, ``r`` and ``outline`` on their grid).

    The fit's sandwich (HC1 per block, or CR1 over clusters of
    ``CLUSTER_PX`` x ``CLUSTER_PX`` blocks with the shaded look) sums the
    residuals, which the fit has made orthogonal to its Jacobian: the part
    of the error that looks like a shift went into the centre and is missing
    from them.  Per pixel that is a share ~ k / n of each cluster's score
    (CR1's n / (n - k) makes it up); on the blocks' grid a window holds a
    quarter as many samples, the clusters (6 px) a quarter as many, and the
    edge's clusters, which locate the centre, have leverage far above the
    mean.  Measured (realistic seed 0 MJPG, the blocks' fits' residuals and
    Jacobians at the tracked centres, /tmp/chroma2/lev.py): err/se 1.31 /
    1.67 on shots 2 / 7 with CR1, residual correlation between
    neighbouring blocks 0.29 / 0.03, so not the clusters' size.  The
    jackknife's (CR3: each cluster's residuals scaled by ``(I - H_gg)^-1``,
    ``H_gg`` the cluster's block of the hat matrix) states each cluster's
    score as if the cluster had been left out of the fit: 1.03 / 1.21 there.
    """
    if isinstance(shade, SphereLook) and outline is not None:  # as fit_disc: the outline's own radius
        r = outline.radius
    # (I - H_gg)^-1 e_g, H_gg = J_g^T A J_g: each cluster's residuals had it
    # been left out, and their scores' outer products summed; the model's
    # rows, A = (J J^T)^-1 and the centre's block of A meat A with them, in
    # one compiled call (track.window.jackknife_cov, cluster_meat: numpy's
    # einsum and batched solves over zero-padded clusters were ~0.5 ms of a
    # 1 ms fit, its glue ~0.15 s a 1,000 frames; the same to rounding).
    from cuespin.track import window
    felt = np.ascontiguousarray(felt, dtype=np.float64)
    h, w = felt.shape
    use = np.ones(h * w) if ok is None else np.asarray(ok, float).ravel()
    kind, geo = _geometry(r, outline)
    B = max(int(CLUSTER_PX if shade is True else SPHERE_CLUSTER_PX), 1)
    has_shade = g.shade is not None
    cov, stated = window.jackknife_cov(np.ascontiguousarray(y, dtype=np.float64), felt, use, float(g.c[0]),
                                       float(g.c[1]), float(g.b[0]), float(g.b[1]), float(g.G), float(r), kind, geo,
                                       int(U0), int(V0), blur_nodes(float(np.hypot(*g.b))),
                                       np.ascontiguousarray(g.shade, dtype=np.float64) if has_shade else _NO_SHADE,
                                       has_shade, bool(fit_blur), B)
    if not stated:
        return g
    return replace(g, cov=cov, stderr=np.sqrt(np.diag(cov)))


def _failed(reason, c, b, G, it):
    return DiscFit(False, reason, np.asarray(c, float), np.asarray(b, float), float(G),
                   np.full(2, np.nan), float("nan"), it, np.full((2, 2), np.nan))


def moments(D: np.ndarray, u0: int, v0: int, c0, radius: float, n_iter: int = 3):
    """Grey-weighted centroid of a background-subtracted patch, iterated.

    Parameters
    ----------
    D : ndarray, shape (h, w)
        Background-subtracted patch, ball positive (grey levels).
    u0, v0 : int
        Frame coordinates of the patch's top-left pixel.
    c0 : array_like, shape (2,)
        Starting centre (px).
    radius : float
        Window radius (px): ball radius plus a margin for blur and error.
    n_iter : int
        Re-centring iterations.

    Returns
    -------
    ndarray, shape (2,)
        Centroid (px); ``c0`` unchanged if the window holds no signal.
    """
    h, w = D.shape
    uu = np.arange(u0, u0 + w, dtype=float)[None, :]
    vv = np.arange(v0, v0 + h, dtype=float)[:, None]
    c = np.array(c0, dtype=float)
    for _ in range(n_iter):
        win = ((uu - c[0]) ** 2 + (vv - c[1]) ** 2) <= radius * radius
        wgt = np.where(win, D, 0.0)
        tot = wgt.sum()
        if tot <= 0:
            break
        c = np.array([(wgt * uu).sum() / tot, (wgt * vv).sum() / tot])
    return c


# refit_shift's least squares: singular values below this fraction of the
# largest are cut (a blur fitted near zero length, whose rows vanish).
SHIFT_RCOND = 1e-9


def refit_shift(felt_old: np.ndarray, felt_new: np.ndarray, u0: int, v0: int, c, b, G: float,
                r: float, fit_blur: bool, shade=None, outline=None, valid=None, block=1) -> np.ndarray:
    """Change of a converged disc fit's centre (px) when its felt is replaced.

    At the old optimum the old Jacobian ``J_o`` is orthogonal to the
    residual; replacing ``felt`` by ``felt + df`` changes the model by
    ``df (1 - cov)``, so if the new model fits the frame at ``c + dc``,
    ``J_o^T (df (1 - cov) + J_n dc) = 0``: ``dc`` is the first two
    components of ``-(J_o^T J_n)^-1 J_o^T df (1 - cov)``.  No pixels of the
    frame are needed.  ``J_o`` rather than ``J_n`` on the left matters where
    the old felt was badly wrong (a felt that shows ball, where a shot
    stopped near its strike: ``J_o`` is zero there, as those pixels told the
    old fit nothing; with ``J_n`` the shift came out of the wrong sign).
    ``shade``: the fit's look parameters, when it fitted them; ``outline``
    the fit's ellipse, when it used one; ``valid`` (bool, the window's
    shape) the pixels it used, when it left some out (the cue's); ``block``
    :func:`fit_disc`'s (the shift of a fit to block means, on their grid).
    """
    if block_area(block) > 1:
        ok = None if valid is None else np.asarray(valid, bool)
        (U0, V0), (fo, fn, ok) = block_patch(block, u0, v0, felt_old, felt_new, ok)
        cc, rc, bc, ol = _coarse(block, c, r, b, outline)
        return np.array(block_sides(block), float) * refit_shift(fo, fn, U0, V0, cc, bc, G, rc, fit_blur, shade, ol, ok)
    # The rows before the level's (centre, blur) are linear in the felt, with
    # the coverage's derivatives as its coefficient (the disc's rows at
    # level 1 on zero felt); the others do not depend on it.  So one
    # evaluation (two with the look) serves both felts; with the lit
    # sphere's lens blur the felt's share is seen through it too.  Least
    # squares, not solve: a blur fitted near zero length has (almost) zero
    # derivatives (the blur acts at second order there), which must not
    # stop the centre's correction.  All in one compiled call
    # (track.window.felt_shift; the numpy form's ~20 small calls a frame).
    from cuespin.track import window
    c, b = np.asarray(c, float), np.asarray(b, float)
    kind, geo = _geometry(r, outline)
    has_valid = valid is not None
    try:
        return window.felt_shift(np.ascontiguousarray(felt_old, dtype=np.float64),
                                 np.ascontiguousarray(felt_new, dtype=np.float64),
                                 np.asarray(valid, float).ravel() if has_valid else _NO_SHADE, has_valid,
                                 float(c[0]), float(c[1]), float(b[0]), float(b[1]), float(G), float(r), kind, geo,
                                 int(u0), int(v0), blur_nodes(float(np.hypot(*b))),
                                 _NO_SHADE if shade is None else np.ascontiguousarray(shade, dtype=np.float64),
                                 shade is not None, bool(fit_blur), SHIFT_RCOND)
    except np.linalg.LinAlgError:
        return np.zeros(2)


def streak_from_moments(D: np.ndarray, u0: int, v0: int, c, radius: float) -> np.ndarray:
    """Blur vector (px) of a streaked ball from its image's second moments.

    A disc of radius ``r`` smeared over a segment of length ``L`` has
    variance ``r^2/4 + L^2/12`` along the segment and ``r^2/4`` across it,
    so ``L = sqrt(12 (var_major - var_minor))`` along the major axis.  Used
    when no velocity predicts the blur (just after the strike, or after the
    ball was lost).  The sign of the vector is arbitrary (a streak has none).
    """
    h, w = D.shape
    uu = np.arange(u0, u0 + w, dtype=float)[None, :] - c[0]
    vv = np.arange(v0, v0 + h, dtype=float)[:, None] - c[1]
    wgt = np.clip(D, 0, None)
    tot = wgt.sum()
    if tot <= 0:
        return np.zeros(2)
    cov = np.array([[(wgt * uu * uu).sum(), (wgt * uu * vv).sum()],
                    [(wgt * uu * vv).sum(), (wgt * vv * vv).sum()]]) / tot
    vals, vecs = np.linalg.eigh(cov)
    length = np.sqrt(max(12.0 * (vals[1] - vals[0]), 0.0))
    return length * vecs[:, 1]
