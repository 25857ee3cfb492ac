"""The ball fit's per-frame kernel, compiled (numba): coverage, model rows, Gauss-Newton.

The same arithmetic as the numpy reference (:mod:`cuespin.track.reference`:
:func:`~cuespin.render.draw.quadrant_area`,
:func:`~cuespin.track.outline.ellipse_corner_area`, ``model_rows`` and
``fit_disc``), written pixel by pixel: on a 14-px ball's 38 x 38 window the
reference spends more time in numpy's per-call overhead than in arithmetic
(~0.25 ms a Gauss-Newton step, 4-5 steps a frame); here a step is one call.
Every expression keeps the reference's order of operations, so the coverage
and its derivatives agree to the last bit or so and the fits to ~1e-12 px
(sums over pixels and nodes are taken in another order;
``tests/test_track_kernel.py``).

Compiled on first use and cached on disk (``cache=True``: numba's cache
beside this file, or ``NUMBA_CACHE_DIR``), so a process pays the compile
(several seconds) once per installation and then ~0.1 s to load it.  Import
it through :func:`cuespin.track.model.kernel`: importing numba costs ~0.5 s,
which only tracking should pay.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# The ball's image: a disc of radius r (geo = [r]) or an ellipse given by
# its chords (geo = [n, hv, wv, m, wh, hh], cuespin.track.outline._slices).
DISC, ELLIPSE = 0, 1
# fit_disc's outcomes (the reference's reasons, in cuespin.track.model.FIT_REASONS).
FIT_OK, FIT_SINGULAR, FIT_DIVERGED, FIT_NO_CONVERGENCE, FIT_LEFT_PATCH = 0, 1, 2, 3, 4
# The fit's settings, cuespin.track.model's constants, arrive as one array
# (``consts``) in this order: passed, not read as globals, which numba
# would freeze into its cache unseen by a change of model.py.
(MAX_ITER, STEP_TOL_PX, STEP_TOL_SE, AITKEN_COS, AITKEN_RHO_LO, AITKEN_RHO_HI, DAMP_AFTER,
 NO_CONVERGENCE_SE, CLUSTER_PX, BLUR_NODES_PER_PX, MAX_BLUR_NODES, SPHERE_CLUSTER_PX) = range(12)
# The lit sphere's look array: its three coefficients, L (3), H (3), p,
# nz_min, then the lens's PSF sigma (px; 0: none) at this index.
PSF_AT = 11
# The PSF's kernel reaches this many sigmas (the renderer's cv2.GaussianBlur
# on float images: a kernel of round(8 sigma + 1) | 1 taps, ~4 sigma each
# side; the weight beyond is below exp(-8) = 3e-4 of the peak).
PSF_REACH = 4.0



def _jit(**options):
    """``numba.njit`` with its on-disk cache where a cache folder can be
    written (beside this file, the user's cache, or ``NUMBA_CACHE_DIR``);
    else without it (a read-only install: numba refuses ``cache=True``
    there with a RuntimeError), compiled once per process."""
    def wrap(f):
        try:
            return njit(cache=True, **options)(f)
        except RuntimeError:
            return njit(**options)(f)
    return wrap


@_jit(inline="always")
def look_at(X, Y, shade):
    """The ball's look at ``(X, Y)`` (ball radii from its centre) less its
    level: value, its derivatives in ``X`` and ``Y``, and the three basis
    functions its coefficients ``shade[:3]`` multiply.  ``shade`` of 3: the
    quadratic look ``gu X + gv Y + q Q``; of 12: the lit sphere's
    ``a max(n.L, 0) + s max(n.H, 0)^p + q Q`` with ``shade[3:11] = (L, H, p,
    nz_min)``
    (:func:`cuespin.track.model.sphere_basis`, the numpy form).  ``Q = X^2 +
    Y^2 - 1/2`` in both."""
    Q = X * X + Y * Y - 0.5
    if shade.shape[0] < 11:
        gu, gv, q = shade[0], shade[1], shade[2]
        return gu * X + gv * Y + q * Q, gu + 2 * q * X, gv + 2 * q * Y, X, Y, Q
    a, s, q = shade[0], shade[1], shade[2]
    D, S, dDx, dDy, dSx, dSy = sphere_at(X, Y, shade)
    return (a * D + s * S + q * Q, a * dDx + s * dSx + 2 * q * X, a * dDy + s * dSy + 2 * q * Y, D, S, Q)


@_jit(inline="always")
def sphere_at(X, Y, g):
    """:func:`cuespin.track.model.sphere_basis` at one point: ``max(n.L, 0)``,
    ``max(n.H, 0)^p`` and their derivatives in ``X``, ``Y`` (``g[3:11]`` =
    L, H, p, nz_min)."""
    rho2 = X * X + Y * Y
    if rho2 > 1.0:  # past the rim: the renderer's normal clamped to it
        s = 1.0 / math.sqrt(rho2)
        s3 = s * s * s
        nx, ny, nz = X * s, Y * s, 0.0
        nxx, nxy, nyx, nyy, nzx, nzy = s - X * X * s3, -X * Y * s3, -X * Y * s3, s - Y * Y * s3, 0.0, 0.0
    else:
        nx, ny = X, Y
        nz = math.sqrt(1.0 - rho2)
        den = max(nz, g[10])
        nxx, nxy, nyx, nyy, nzx, nzy = 1.0, 0.0, 0.0, 1.0, -X / den, -Y / den
    nl = nx * g[3] + ny * g[4] + nz * g[5]
    D, dDx, dDy = 0.0, 0.0, 0.0
    if nl > 0.0:
        D = nl
        dDx = nxx * g[3] + nyx * g[4] + nzx * g[5]
        dDy = nxy * g[3] + nyy * g[4] + nzy * g[5]
    nh = nx * g[6] + ny * g[7] + nz * g[8]
    S, dSx, dSy = 0.0, 0.0, 0.0
    if nh > 0.0:
        p = g[9]
        S = nh ** p
        f = p * S / nh  # p nh^(p-1), one power
        dSx = f * (nxx * g[6] + nyx * g[7] + nzx * g[8])
        dSy = f * (nxy * g[6] + nyy * g[7] + nzy * g[8])
    return D, S, dDx, dDy, dSx, dSy


@_jit()
def _disc_arc(z, r2, r):
    """``quadrant_area``'s A(z): half the disc's area left of ``z``, plus a constant."""
    return 0.5 * (z * math.sqrt(max(r2 - z * z, 0.0)) + r2 * math.asin(z / r)) + 0.25 * math.pi * r2


@_jit()
def _disc_corners(xe, ye, r, G):
    """:func:`cuespin.render.draw.quadrant_area` on the grid ``ye[i], xe[j]`` into ``G``."""
    nx, ny = xe.shape[0], ye.shape[0]
    r2 = r * r
    x = np.empty(nx)
    Ax = np.empty(nx)
    for j in range(nx):
        x[j] = min(max(xe[j], -r), r)
        Ax[j] = _disc_arc(x[j], r2, r)
    for i in range(ny):
        y = min(max(ye[i], -r), r)
        ya = abs(y)
        c = math.sqrt(max(r2 - ya * ya, 0.0))
        Ac = _disc_arc(c, r2, r)
        Amc = _disc_arc(-c, r2, r)
        for j in range(nx):
            xj = x[j]
            m = ((Ax[j] if xj <= -c else Amc) + ya * (min(max(xj, -c), c) + c)
                 + ((Ax[j] if xj >= c else Ac) - Ac))
            G[i, j] = Ax[j] + m if y >= 0 else Ax[j] - m


@_jit()
def _seg(z, hv, wv):
    """``ellipse_corner_area``'s seg(z)."""
    xi = min(max(z / wv, -1.0), 1.0)
    return 0.5 * hv * wv * (xi * math.sqrt(max(1.0 - xi * xi, 0.0)) + math.asin(xi))


@_jit()
def _poly(z, y, n):
    return (0.5 * n * z - y) * z


@_jit()
def _part(xc, Sx, a, b, Sa, Sb, pa, y, n, k):
    """``ellipse_corner_area``'s part(a, b, k), with seg(a), seg(b), poly(a) given."""
    u = min(max(xc, a), b)
    Su = Sa if xc <= a else (Sb if xc >= b else Sx)
    return _poly(u, y, n) - pa + k * (Su - Sa)


@_jit()
def _ellipse_corners(xe, ye, geo, G):
    """:func:`cuespin.track.outline.ellipse_corner_area` on the grid ``ye[i], xe[j]`` into ``G``."""
    n, hv, wv, m, wh, hh = geo[0], geo[1], geo[2], geo[3], geo[4], geo[5]
    nx, ny = xe.shape[0], ye.shape[0]
    xc = np.empty(nx)
    Sx = np.empty(nx)
    for j in range(nx):
        xc[j] = min(max(xe[j], -wv), wv)
        Sx[j] = _seg(xc[j], hv, wv)
    Smw = _seg(-wv, hv, wv)
    out = wv
    for i in range(ny):
        y = ye[i]
        eta = min(max(y / hh, -1.0), 1.0)
        half = wh * math.sqrt(max(1.0 - eta * eta, 0.0))
        xl, xr = m * y - half, m * y + half
        above, below = y >= hh, y <= -hh
        # interval(): the upper arc above y on [a2, b2], the lower below it on [a3, b3].
        a2 = -wv if below else (out if above else (xl if y >= n * xl else -wv))
        b2 = wv if below else (out if above else (xr if y >= n * xr else wv))
        b2 = max(a2, b2)
        a3 = -wv if above else (out if below else (xl if y <= n * xl else -wv))
        b3 = wv if above else (out if below else (xr if y <= n * xr else wv))
        b3 = max(a3, b3)
        Sa2, Sb2, Sa3, Sb3 = _seg(a2, hv, wv), _seg(b2, hv, wv), _seg(a3, hv, wv), _seg(b3, hv, wv)
        pa2, pa3, pmw = _poly(a2, y, n), _poly(a3, y, n), _poly(-wv, y, n)
        for j in range(nx):
            T1 = 2.0 * Sx[j] + 0.5 * math.pi * hv * wv
            lower = _poly(xc[j], y, n) - pmw - (Sx[j] - Smw)
            G[i, j] = (T1 - _part(xc[j], Sx[j], a2, b2, Sa2, Sb2, pa2, y, n, 1.0) + lower
                       - _part(xc[j], Sx[j], a3, b3, Sa3, Sb3, pa3, y, n, -1.0))


@_jit()
def coverage(cu, cv, kind, geo, u0, v0, w, h, cov, du, dv):
    """Exact pixel coverage of the ball's image centred at ``(cu, cv)`` over
    the ``h x w`` window at ``(u0, v0)``, and its derivatives in the centre,
    into ``cov``, ``du``, ``dv`` (h, w):
    :func:`cuespin.track.model.disc_with_gradient` or
    :func:`cuespin.track.outline.ellipse_with_gradient`."""
    xe = np.empty(w + 1)
    ye = np.empty(h + 1)
    for j in range(w + 1):
        xe[j] = (u0 + j) - 0.5 - cu
    for i in range(h + 1):
        ye[i] = (v0 + i) - 0.5 - cv
    G = np.empty((h + 1, w + 1))
    if kind == DISC:
        r = geo[0]
        _disc_corners(xe, ye, r, G)
        # Chords on the column edges (vert) and row edges (horz): model._chords.
        sx = np.empty(w + 1)
        for j in range(w + 1):
            sx[j] = math.sqrt(max(r * r - xe[j] * xe[j], 0.0))
        sy = np.empty(h + 1)
        for i in range(h + 1):
            sy[i] = math.sqrt(max(r * r - ye[i] * ye[i], 0.0))
        lo_x, hi_x, lo_y, hi_y = -sx, sx, -sy, sy
    else:
        n, hv, wv, m, wh, hh = geo[0], geo[1], geo[2], geo[3], geo[4], geo[5]
        _ellipse_corners(xe, ye, geo, G)
        lo_x, hi_x = np.empty(w + 1), np.empty(w + 1)  # the vertical chord at column edge j: [yb, yt]
        for j in range(w + 1):
            sv = hv * math.sqrt(max(1.0 - (xe[j] / wv) ** 2, 0.0))
            lo_x[j], hi_x[j] = n * xe[j] - sv, n * xe[j] + sv
        lo_y, hi_y = np.empty(h + 1), np.empty(h + 1)  # the horizontal chord at row edge i: [xl, xr]
        for i in range(h + 1):
            sh = wh * math.sqrt(max(1.0 - (ye[i] / hh) ** 2, 0.0))
            lo_y[i], hi_y[i] = m * ye[i] - sh, m * ye[i] + sh
    for i in range(h):
        for j in range(w):
            cov[i, j] = G[i + 1, j + 1] - G[i + 1, j] - G[i, j + 1] + G[i, j]
            v_l = max(min(ye[i + 1], hi_x[j]) - max(ye[i], lo_x[j]), 0.0)
            v_r = max(min(ye[i + 1], hi_x[j + 1]) - max(ye[i], lo_x[j + 1]), 0.0)
            h_t = max(min(xe[j + 1], hi_y[i]) - max(xe[j], lo_y[i]), 0.0)
            h_b = max(min(xe[j + 1], hi_y[i + 1]) - max(xe[j], lo_y[i + 1]), 0.0)
            du[i, j] = v_l - v_r
            dv[i, j] = h_t - h_b


@_jit()
def model_rows(c0, c1, b0, b1, G, felt, r, kind, geo, u0, v0, taus, shade, has_shade, blur_rows, m, JT):
    """:func:`cuespin.track.reference.model_rows` into ``m`` (h*w) and ``JT``
    (k, h*w): the model and its Jacobian's rows, centre, blur (when
    ``blur_rows``), level and the look's three (when ``has_shade``); with
    the lit sphere's lens blur (``shade[11]``, the PSF's sigma, px, > 0)
    each of them convolved with it (:func:`psf_blur`)."""
    _sharp_rows(c0, c1, b0, b1, G, felt, r, kind, geo, u0, v0, taus, shade, has_shade, blur_rows, m, JT)
    if has_shade and shade.shape[0] > PSF_AT and shade[PSF_AT] > 0.0:
        h, w = felt.shape
        psf_blur(m.reshape(1, h, w), shade[PSF_AT])
        psf_blur(JT.reshape(JT.shape[0], h, w), shade[PSF_AT])


@_jit()
def psf_weights(sigma):
    """The sampled Gaussian of ``sigma`` (px) out to ``PSF_REACH`` sigmas,
    normalised: the lens's PSF as the renderer applies it
    (``cv2.GaussianBlur`` of the pixel-integrated image, its kernel out to
    4 sigma, cuespin.render.draw.gaussian)."""
    rad = int(math.ceil(PSF_REACH * sigma))
    wts = np.empty(2 * rad + 1)
    tot = 0.0
    for d in range(-rad, rad + 1):
        wts[d + rad] = math.exp(-0.5 * (d / sigma) ** 2)
        tot += wts[d + rad]
    for d in range(2 * rad + 1):
        wts[d] /= tot
    return wts


@_jit(fastmath={"reassoc", "contract"})
def psf_blur(planes, sigma):
    """Each of ``planes`` (k, h, w) convolved in place with the separable
    Gaussian of ``sigma`` (px), zero outside the window (the model is zero
    off the ball, which the window holds with a margin).  Only the box
    within the PSF's reach of the planes' non-zero values is computed (the
    ball covers a third of its window), through a zero-padded copy whose
    taps have fixed bounds (the loops over a row vectorise; with bounds
    per pixel a 37 x 37 window's nine planes took 0.25 ms)."""
    k, h, w = planes.shape
    wts = psf_weights(sigma)
    n_w = wts.shape[0]
    rad = (n_w - 1) // 2
    i_lo, i_hi, j_lo, j_hi = h, -1, w, -1
    for a in range(k):
        for i in range(h):
            for j in range(w):
                if planes[a, i, j] != 0.0:
                    i_lo, i_hi = min(i_lo, i), max(i_hi, i)
                    j_lo, j_hi = min(j_lo, j), max(j_hi, j)
    if i_hi < 0:
        return
    i0, i1 = max(i_lo - rad, 0), min(i_hi + rad + 1, h)
    j0, j1 = max(j_lo - rad, 0), min(j_hi + rad + 1, w)
    H, W = i1 - i0, j1 - j0
    # P[i + rad, j + rad] = planes[a, i0 + i, j0 + j] on the non-zero box, zero around it.
    P = np.zeros((H + 2 * rad, W + 2 * rad))
    T = np.zeros((H + 2 * rad, W))
    for a in range(k):
        for i in range(i_lo, i_hi + 1):
            for j in range(j_lo, j_hi + 1):
                P[i - i0 + rad, j - j0 + rad] = planes[a, i, j]
        for ii in range(i_lo - i0 + rad, i_hi - i0 + rad + 1):  # along the rows holding a value
            for j in range(W):
                T[ii, j] = 0.0
            for d in range(n_w):
                wd = wts[d]
                for j in range(W):
                    T[ii, j] += wd * P[ii, j + d]
        for i in range(H):  # then down the columns
            for j in range(W):
                planes[a, i0 + i, j0 + j] = 0.0
            for d in range(n_w):
                wd = wts[d]
                for j in range(W):
                    planes[a, i0 + i, j0 + j] += wd * T[i + d, j]


@_jit()
def _sharp_rows(c0, c1, b0, b1, G, felt, r, kind, geo, u0, v0, taus, shade, has_shade, blur_rows, m, JT):
    """:func:`model_rows` before the lens's blur."""
    h, w = felt.shape
    n_t = taus.shape[0]
    R = JT.reshape(JT.shape[0], h, w)
    M = m.reshape(h, w)
    i0 = 4 if blur_rows else 2
    if n_t == 1 and taus[0] == 0.0:
        cov = np.empty((h, w))
        du = np.empty((h, w))
        dv = np.empty((h, w))
        coverage(c0, c1, kind, geo, u0, v0, w, h, cov, du, dv)
        for i in range(h):
            Y = ((v0 + i) - c1) / r
            for j in range(w):
                if blur_rows:
                    R[2, i, j] = 0.0
                    R[3, i, j] = 0.0
                R[i0, i, j] = cov[i, j]
                if not has_shade:
                    contrast = G - felt[i, j]
                    R[0, i, j] = du[i, j] * contrast
                    R[1, i, j] = dv[i, j] * contrast
                    M[i, j] = contrast * cov[i, j]
                elif cov[i, j] == 0.0 and du[i, j] == 0.0 and dv[i, j] == 0.0:
                    # Off the ball: the look is multiplied by zero (half the window's pixels).
                    for a in range(4):
                        R[i0 + a, i, j] = 0.0
                    R[0, i, j] = 0.0
                    R[1, i, j] = 0.0
                    M[i, j] = 0.0
                else:
                    X = ((u0 + j) - c0) / r
                    val, lx, ly, f1, f2, f3 = look_at(X, Y, shade)
                    ball = (G - felt[i, j]) + val
                    R[0, i, j] = du[i, j] * ball - cov[i, j] * (lx / r)
                    R[1, i, j] = dv[i, j] * ball - cov[i, j] * (ly / r)
                    R[i0 + 1, i, j] = cov[i, j] * f1
                    R[i0 + 2, i, j] = cov[i, j] * f2
                    R[i0 + 3, i, j] = cov[i, j] * f3
                    M[i, j] = cov[i, j] * ball
        return
    covs = np.empty((n_t, h, w))
    gus = np.empty((n_t, h, w))
    gvs = np.empty((n_t, h, w))
    for t in range(n_t):
        coverage(c0 + b0 * taus[t], c1 + b1 * taus[t], kind, geo, u0, v0, w, h, covs[t], gus[t], gvs[t])
    if not has_shade:
        for i in range(h):
            for j in range(w):
                sc, su, sv, tu, tv = covs[0, i, j], gus[0, i, j], gvs[0, i, j], 0.0, 0.0
                for t in range(1, n_t):
                    sc += covs[t, i, j]
                    su += gus[t, i, j]
                    sv += gvs[t, i, j]
                for t in range(n_t):
                    tu += taus[t] * gus[t, i, j]
                    tv += taus[t] * gvs[t, i, j]
                cov = sc / n_t
                contrast = (G - felt[i, j]) / n_t
                R[0, i, j] = su * contrast
                R[1, i, j] = sv * contrast
                if blur_rows:
                    R[2, i, j] = tu * contrast
                    R[3, i, j] = tv * contrast
                R[i0, i, j] = cov
                M[i, j] = (G - felt[i, j]) * cov
        return
    for i in range(h):
        for j in range(w):
            s_du, s_dv, t_du, t_dv, s_c, s_x, s_y, s_q, s_m = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
            for t in range(n_t):
                if covs[t, i, j] == 0.0 and gus[t, i, j] == 0.0 and gvs[t, i, j] == 0.0:
                    continue  # off the ball at this node: every term is zero
                X = ((u0 + j) - (c0 + b0 * taus[t])) / r
                Y = ((v0 + i) - (c1 + b1 * taus[t])) / r
                val, lx, ly, f1, f2, f3 = look_at(X, Y, shade)
                ball = (G + val) - felt[i, j]
                cv_ = covs[t, i, j]
                node_du = gus[t, i, j] * ball - cv_ * (lx / r)
                node_dv = gvs[t, i, j] * ball - cv_ * (ly / r)
                s_du += node_du
                s_dv += node_dv
                t_du += taus[t] * node_du
                t_dv += taus[t] * node_dv
                s_c += cv_
                s_x += cv_ * f1
                s_y += cv_ * f2
                s_q += cv_ * f3
                s_m += cv_ * ball
            R[0, i, j] = s_du / n_t
            R[1, i, j] = s_dv / n_t
            if blur_rows:
                R[2, i, j] = t_du / n_t
                R[3, i, j] = t_dv / n_t
            R[i0, i, j] = s_c / n_t
            R[i0 + 1, i, j] = s_x / n_t
            R[i0 + 2, i, j] = s_y / n_t
            R[i0 + 3, i, j] = s_q / n_t
            M[i, j] = s_m / n_t


@_jit()
def blur_nodes(blur_px, consts):
    """:func:`cuespin.track.model.blur_nodes`."""
    if blur_px < 0.25:
        return np.zeros(1)
    n = int(min(consts[MAX_BLUR_NODES], max(2.0, math.ceil(blur_px * consts[BLUR_NODES_PER_PX]))))
    return (np.arange(n) + 0.5) / n - 0.5


@_jit(fastmath={"reassoc", "contract"})
def _dot(x, y):
    """Sum of ``x * y`` (vectorised: the order of the sum is free, as in BLAS)."""
    s = 0.0
    for p in range(x.shape[0]):
        s += x[p] * y[p]
    return s


@_jit(fastmath={"reassoc", "contract"})
def _gram(X, wt, weighted):
    """``X @ X.T``, or ``(X * wt) @ X.T`` when ``weighted``."""
    k, n = X.shape
    out = np.empty((k, k))
    for a in range(k):
        for b in range(a + 1):
            s = 0.0
            if weighted:
                for p in range(n):
                    s += X[a, p] * X[b, p] * wt[p]
            else:
                for p in range(n):
                    s += X[a, p] * X[b, p]
            out[a, b] = s
            out[b, a] = s
    return out


@_jit()
def _matvec(A, x):
    out = np.empty(A.shape[0])
    for a in range(A.shape[0]):
        out[a] = _dot(A[a], x)
    return out


@_jit()
def _inverse(M):
    """``np.linalg.inv`` for the normal equations' few parameters: Gauss-Jordan
    with partial pivoting (LAPACK's getrf pivots alike); None when a pivot is
    exactly zero (where numpy raises)."""
    k = M.shape[0]
    a = M.copy()
    inv = np.eye(k)
    for col in range(k):
        piv = col
        for i in range(col + 1, k):
            if abs(a[i, col]) > abs(a[piv, col]):
                piv = i
        if a[piv, col] == 0.0:
            return False, inv
        if piv != col:
            for j in range(k):
                a[col, j], a[piv, j] = a[piv, j], a[col, j]
                inv[col, j], inv[piv, j] = inv[piv, j], inv[col, j]
        d = a[col, col]
        for j in range(k):
            a[col, j] /= d
            inv[col, j] /= d
        for i in range(k):
            if i != col and a[i, col] != 0.0:
                f = a[i, col]
                for j in range(k):
                    a[i, j] -= f * a[col, j]
                    inv[i, j] -= f * inv[col, j]
    return True, inv


@_jit()
def _centre_cov(A, meat):
    """The first 2 x 2 block of ``A @ meat @ A`` (A symmetric)."""
    k = A.shape[0]
    V = np.zeros((2, 2))
    for a in range(2):
        for b in range(2):
            s = 0.0
            for i in range(k):
                for j in range(k):
                    s += A[a, i] * meat[i, j] * A[j, b]
            V[a, b] = s
    return V


@_jit()
def fit(y, felt, use, has_valid, c, b, G, r, kind, geo, u0, v0, has_shade, look_geo, fit_blur, consts):
    """:func:`cuespin.track.reference.fit_disc`'s Gauss-Newton loop and
    sandwich, in place on ``c`` (2), ``b`` (2); ``y`` is the frame less the
    felt (h*w), ``use`` the pixels used (0/1, h*w; read when ``has_valid``);
    ``look_geo`` the lit sphere's geometry (8: L, H, p, nz_min) or empty
    (the quadratic look, when ``has_shade``).

    Returns (outcome, G, look (3, or 12 with the geometry), iterations,
    stderr (2), cov (2, 2), rms).
    """
    h, w = felt.shape
    npx = h * w
    n_look = 3 if has_shade else 0
    n_par = (5 if fit_blur else 3) + n_look
    # The look's coefficients, then (the lit sphere's) its fixed geometry.
    look = np.zeros(3 + look_geo.shape[0])
    look[3:] = look_geo
    taus = blur_nodes(math.hypot(b[0], b[1]), consts)
    n_use = 0.0
    for p in range(npx):
        n_use += use[p]
    m = np.empty(npx)
    JT = np.empty((n_par, npx))
    res = np.empty(npx)
    A = np.empty((n_par, n_par))
    Jtr = np.empty(n_par)
    invertible = True
    step = np.zeros(n_par)
    raw = np.zeros(n_par)
    prev = np.zeros(n_par)
    have_prev = False
    nan2 = np.full(2, np.nan)
    nan22 = np.full((2, 2), np.nan)
    it = 0
    converged = False
    for it in range(1, int(consts[MAX_ITER]) + 1):
        model_rows(c[0], c[1], b[0], b[1], G, felt, r, kind, geo, u0, v0, taus, look, has_shade, fit_blur, m, JT)
        for p in range(npx):
            res[p] = y[p] - m[p]
        if has_valid:
            for p in range(npx):
                res[p] *= use[p]
            for a in range(n_par):
                for p in range(npx):
                    JT[a, p] *= use[p]
        Jtr = _matvec(JT, res)
        invertible, A = _inverse(_gram(JT, res, False))
        if not invertible:
            return FIT_SINGULAR, G, look, it, nan2, nan22, np.nan
        step = _matvec(A, Jtr)
        finite = True
        for a in range(n_par):
            if not np.isfinite(step[a]):
                finite = False
        if not finite or abs(step[0]) > w or abs(step[1]) > h:
            return FIT_DIVERGED, G, look, it, nan2, nan22, np.nan
        move = math.hypot(step[0], step[1])
        # The centre's standard error from the pooled residual (after this step).
        s2 = max(_dot(res, res) - _dot(Jtr, step), 0.0) / max(n_use - n_par, 1.0)
        done = move < consts[STEP_TOL_PX] or move < consts[STEP_TOL_SE] * math.sqrt(s2 * min(A[0, 0], A[1, 1]))
        raw = step
        if have_prev and not done:
            pp = _dot(prev, prev)
            rho = _dot(step, prev) / pp if pp > 0 else 0.0
            if abs(rho) * math.sqrt(pp) > consts[AITKEN_COS] * math.sqrt(_dot(step, step)):
                step = step / (1.0 - min(max(rho, consts[AITKEN_RHO_LO]), consts[AITKEN_RHO_HI]))
        prev = raw
        have_prev = True
        if it > consts[DAMP_AFTER]:
            step = 0.5 * step
        c[0] += step[0]
        c[1] += step[1]
        G += step[n_par - 1 - n_look]
        if has_shade:
            for a in range(3):
                look[a] += step[n_par - 3 + a]
        if fit_blur:
            b[0] += step[2]
            b[1] += step[3]
            taus = blur_nodes(math.hypot(b[0], b[1]), consts)
        if done:
            converged = True
            break
    if not converged:
        # Still moving: accept only a step far below the centre's own
        # uncertainty (the sandwich), which no estimate can resolve.
        V = _centre_cov(A, _gram(JT, res * res, True))
        se_min = min(math.sqrt(max(V[0, 0], 0.0)), math.sqrt(max(V[1, 1], 0.0)))
        if not math.hypot(step[0], step[1]) < consts[NO_CONVERGENCE_SE] * se_min:
            return FIT_NO_CONVERGENCE, G, look, it, nan2, nan22, np.nan
    # Residual and covariance from the last evaluation (see the reference).
    dof = max(int(n_use) - n_par, 1)
    rms = math.sqrt(max(_dot(res, res) - _dot(Jtr, raw), 0.0) / dof)
    inside = (u0 - 0.5 <= c[0] <= u0 + w - 0.5) and (v0 - 0.5 <= c[1] <= v0 + h - 0.5)
    if not inside:
        return FIT_LEFT_PATCH, G, look, it, nan2, nan22, np.nan
    # The sandwich: clustered in blocks of CLUSTER_PX (SPHERE_CLUSTER_PX with
    # the lit sphere) with the look, HC1 without (or with a block of 0).
    B = int(consts[SPHERE_CLUSTER_PX] if look_geo.shape[0] > 0 else consts[CLUSTER_PX])
    if has_shade and B > 0:
        nbh, nbw = (h + B - 1) // B, (w + B - 1) // B
        S = np.zeros((n_par, nbh * nbw))
        for a in range(n_par):
            for i in range(h):
                for j in range(w):
                    p = i * w + j
                    S[a, (i // B) * nbw + j // B] += JT[a, p] * res[p]
        nb = nbh * nbw
        meat = _gram(S, res, False) * (n_use / dof) * nb / max(nb - 1, 1)
    else:
        meat = _gram(JT, res * res, True) * (n_use / dof)
    V = _centre_cov(A, meat)
    cov = np.empty((2, 2))
    cov[0, 0], cov[1, 1] = V[0, 0], V[1, 1]
    cov[0, 1] = cov[1, 0] = 0.5 * (V[0, 1] + V[1, 0])
    se = np.empty(2)
    se[0] = math.sqrt(max(cov[0, 0], 0.0))
    se[1] = math.sqrt(max(cov[1, 1], 0.0))
    return FIT_OK, G, look, it, se, cov, rms
