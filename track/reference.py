"""The ball fit in numpy: the reference the compiled kernel is tested against.

:func:`model_rows` and :func:`fit_disc` are the numpy forms of
:func:`cuespin.track.model.streak_model`'s rows and of
:func:`cuespin.track.model.fit_disc`, which run compiled
(:mod:`cuespin.track.kernel`, the one production path); they are kept to
show what the kernel computes in array form and to check it
(``tests/test_track_kernel.py``: the same model to ~1e-13 and the same
fitted centres and stated errors to ~1e-10 px).
"""

from __future__ import annotations

import numpy as np

from cuespin.track.kernel import PSF_AT, PSF_REACH
from cuespin.track.model import (AITKEN_COS, AITKEN_RHO, CLUSTER_PX, DAMP_AFTER, MAX_ITER, NO_CONVERGENCE_SE,
                                 SPHERE_CLUSTER_PX, STEP_TOL_PX, STEP_TOL_SE, DiscFit, SphereLook, _failed,
                                 _fit_blocks, block_area, blur_nodes, coverage_with_gradient, look_value)


def model_rows(c, b, G, felt, r, u0, v0, taus, shade=None, blur_rows=True, outline=None):
    """:func:`~cuespin.track.model.streak_model` with its Jacobian transposed, shape (k, h*w), and
    the blur's two rows left out when ``blur_rows`` is False (k = 3, or 6
    with ``shade``).  The fit's working form: contiguous rows make ``J^T J``
    one product, and the columns a fit does not read are never built.  A
    sharp ball (one node at 0) is computed on 2-D arrays, without the sums
    over nodes (measured: half of the evaluation's time went to overheads
    of arrays this small).  With the lit sphere's lens blur (``shade[PSF_AT]``
    > 0) the model and every row are convolved with its PSF (:func:`psf_blur`).
    """
    m, JT = _sharp_rows(c, b, G, felt, r, u0, v0, taus, shade, blur_rows, outline)
    if shade is not None and len(shade) > PSF_AT and shade[PSF_AT] > 0:
        h, w = np.shape(felt)
        m = psf_blur(m[None], shade[PSF_AT])[0]
        JT = psf_blur(JT.reshape(-1, h, w), shade[PSF_AT]).reshape(JT.shape[0], -1)
    return m, JT


def psf_blur(planes, sigma: float) -> np.ndarray:
    """``planes`` (k, h, w) each convolved with the sampled Gaussian of
    ``sigma`` (px), zero outside: :func:`cuespin.track.kernel.psf_blur`."""
    rad = int(np.ceil(PSF_REACH * sigma))
    wts = np.exp(-0.5 * (np.arange(-rad, rad + 1) / sigma) ** 2)
    wts /= wts.sum()
    out = np.apply_along_axis(np.convolve, 2, planes, wts, mode="same")
    return np.apply_along_axis(np.convolve, 1, out, wts, mode="same")


def _sharp_rows(c, b, G, felt, r, u0, v0, taus, shade=None, blur_rows=True, outline=None):
    """:func:`model_rows` before the lens's blur."""
    h, w = felt.shape
    taus = np.asarray(taus, float)
    n = len(taus)
    felt = np.asarray(felt, float)
    k = (5 if blur_rows else 3) + (3 if shade is not None else 0)
    JT = np.empty((k, h * w))
    R = JT.reshape(k, h, w)
    if n == 1 and taus[0] == 0.0:
        cov, du, dv = coverage_with_gradient(c[0], c[1], r, u0, v0, w, h, outline)  # (h, w)
        i = 2
        if blur_rows:  # a single node at tau = 0: the blur acts at second order only
            R[2:4] = 0.0
            i = 4
        if shade is None:
            contrast = G - felt
            np.multiply(du, contrast, out=R[0])
            np.multiply(dv, contrast, out=R[1])
            R[i] = cov
            return contrast * cov, JT
        X = (np.arange(u0, u0 + w) - c[0]) / r                     # (w,)
        Y = ((np.arange(v0, v0 + h) - c[1]) / r)[:, None]          # (h, 1)
        val, lx, ly, f1, f2, f3 = look_value(X, Y, shade)
        ball = (G - felt) + val
        # d/d(centre): the edge moves (coverage) and the look moves with it.
        np.subtract(du * ball, cov * (lx / r), out=R[0])
        np.subtract(dv * ball, cov * (ly / r), out=R[1])
        R[i] = cov
        np.multiply(cov, f1, out=R[i + 1])
        np.multiply(cov, f2, out=R[i + 2])
        np.multiply(cov, f3, out=R[i + 3])
        return cov * ball, JT
    cu = c[0] + b[0] * taus
    cv = c[1] + b[1] * taus
    covs, gus, gvs = coverage_with_gradient(cu, cv, r, u0, v0, w, h, outline)  # (n, h, w)
    i = 4 if blur_rows else 2
    if shade is None:
        cov = covs.sum(axis=0) / n
        contrast = (G - felt) / n
        R[0] = gus.sum(axis=0) * contrast
        R[1] = gvs.sum(axis=0) * contrast
        if blur_rows:
            R[2] = np.tensordot(taus, gus, axes=1) * contrast
            R[3] = np.tensordot(taus, gvs, axes=1) * contrast
        R[i] = cov
        return (G - felt) * cov, JT
    X = (np.arange(u0, u0 + w)[None, None, :] - cu[:, None, None]) / r   # (n, 1, w)
    Y = (np.arange(v0, v0 + h)[None, :, None] - cv[:, None, None]) / r   # (n, h, 1)
    val, lx, ly, f1, f2, f3 = look_value(X, Y, shade)
    ball = (G + val) - felt                                              # (n, h, w)
    # d/d(node centre): the edge moves (coverage) and the look moves with it.
    node_du = gus * ball - covs * (lx / r)
    node_dv = gvs * ball - covs * (ly / r)
    R[0] = node_du.sum(axis=0) / n
    R[1] = node_dv.sum(axis=0) / n
    if blur_rows:
        R[2] = np.tensordot(taus, node_du, axes=1) / n
        R[3] = np.tensordot(taus, node_dv, axes=1) / n
    R[i] = covs.sum(axis=0) / n
    R[i + 1] = (covs * f1).sum(axis=0) / n
    R[i + 2] = (covs * f2).sum(axis=0) / n
    R[i + 3] = (covs * f3).sum(axis=0) / n
    return (covs * ball).sum(axis=0) / n, JT



def fit_disc(frame: np.ndarray, felt: np.ndarray, u0: int, v0: int, c0, r: float, G0: float,
             b0=(0.0, 0.0), fit_blur: bool = False, shade: bool = False, valid=None,
             outline=None, block=1, jackknife: bool = True) -> DiscFit:
    """:func:`cuespin.track.model.fit_disc` in numpy (same arguments and result)."""
    if block_area(block) > 1:
        return _fit_blocks(block, frame, felt, u0, v0, c0, r, G0, b0, fit_blur, shade, valid, outline, fit=fit_disc,
                           jackknife=jackknife)
    felt = np.asarray(felt, dtype=np.float64)
    h, w = felt.shape
    y = (np.asarray(frame, dtype=np.float64) - felt).ravel()
    use = np.ones(h * w) if valid is None else np.asarray(valid, float).ravel()
    c = np.array(c0, dtype=float)
    b = np.array(b0, dtype=float)
    G = float(G0)
    look = None
    if shade:  # the coefficients, then (the lit sphere's) its geometry
        look = np.r_[np.zeros(3), shade.geometry() if isinstance(shade, SphereLook) else ()]
    sphere = isinstance(shade, SphereLook)
    if sphere and outline is not None:  # scaled by the outline's own radius, as model.fit_disc
        r = outline.radius
    n_look = 3 if shade else 0
    n_par = (5 if fit_blur else 3) + n_look
    taus = blur_nodes(np.hypot(*b))
    n_use = float(use.sum())
    it = 0
    prev = None
    for it in range(1, MAX_ITER + 1):
        m, JT = model_rows(c, b, G, felt, r, u0, v0, taus, look, fit_blur, outline)  # J^T: (n_par, h*w)
        res = y - m.ravel()
        if valid is not None:  # all ones otherwise: skip two products per step
            res *= use
            JT *= use
        JtJ = JT @ JT.T
        Jtr = JT @ res
        try:
            A = np.linalg.inv(JtJ)
        except np.linalg.LinAlgError:
            return _failed("singular normal equations", c, b, G, it)
        step = A @ Jtr
        if not np.all(np.isfinite(step)) or abs(step[0]) > w or abs(step[1]) > h:
            return _failed("diverged", c, b, G, it)
        move = np.hypot(step[0], step[1])
        # The centre's standard error from the pooled residual (after this step).
        s2 = max(res @ res - Jtr @ step, 0.0) / max(n_use - n_par, 1.0)
        done = move < STEP_TOL_PX or move < STEP_TOL_SE * np.sqrt(s2 * min(A[0, 0], A[1, 1]))
        raw = step
        if prev is not None and not done:
            pp = prev @ prev
            rho = (step @ prev) / pp if pp > 0 else 0.0
            if abs(rho) * np.sqrt(pp) > AITKEN_COS * np.sqrt(step @ step):
                step = step / (1.0 - np.clip(rho, *AITKEN_RHO))
        prev = raw
        if it > DAMP_AFTER:
            step = 0.5 * step
        c += step[:2]
        G += step[n_par - 1 - n_look]
        if shade:
            look[:3] += step[-3:]
        if fit_blur:
            b += step[2:4]
            taus = blur_nodes(np.hypot(*b))
        if done:
            break
    else:
        # Still moving: accept only a step far below the centre's own
        # uncertainty (the sandwich below), which no estimate can resolve.
        se_now = np.sqrt(np.clip(np.diag(A @ ((JT * (res * res)) @ JT.T) @ A)[:2], 0, None))
        if not np.hypot(step[0], step[1]) < NO_CONVERGENCE_SE * se_now.min():
            return _failed(f"no convergence in {MAX_ITER} iterations", c, b, G, it)
    # Residual and covariance from the last evaluation: the final step moved
    # the centre by under STEP_TOL_PX or a tenth of its error, which changes
    # neither measurably.
    dof = max(int(n_use) - n_par, 1)
    rms = float(np.sqrt(max(res @ res - Jtr @ raw, 0.0) / dof))
    inside = (u0 - 0.5 <= c[0] <= u0 + w - 0.5) and (v0 - 0.5 <= c[1] <= v0 + h - 0.5)
    if not inside:
        return _failed("centre left the patch", c, b, G, it)
    # Standard errors by the sandwich (heteroscedasticity-consistent, HC1):
    # the noise is not the same in every pixel.  At low sensor noise the
    # 8-bit rounding is most of it, and it sits on the ball's edge, the
    # pixels that locate it, while felt and ball rounded to the same integer
    # every frame show almost none: one pooled RMS stated errors 3.6x too
    # small at noise 0.08 (benchmarks/track.py accuracy, column err/se).  It
    # equals the sandwich when the noise is the same everywhere.
    # With the look fitted (shaded), what the model leaves (the lens's blur
    # on the edge, markings turning with the spin) is correlated between
    # neighbouring pixels, which HC1 counts as independent: the residuals
    # are then summed over blocks of CLUSTER_PX x CLUSTER_PX pixels first
    # (the cluster-robust sandwich, CR1).
    # The lit sphere's look leaves little of that (SPHERE_CLUSTER_PX, 0: HC1).
    try:
        B = SPHERE_CLUSTER_PX if sphere else CLUSTER_PX
        if shade and B > 0:
            S = np.zeros((n_par, h + (-h % B), w + (-w % B)))
            S[:, :h, :w] = (JT * res).reshape(n_par, h, w)
            S = S.reshape(n_par, S.shape[1] // B, B, S.shape[2] // B, B).sum(axis=(2, 4)).reshape(n_par, -1)
            nb = S.shape[1]
            meat = S @ S.T * (n_use / dof) * nb / max(nb - 1, 1)
        else:
            meat = (JT * (res * res)) @ JT.T * (n_use / dof)
        cov = (A @ meat @ A)[:2, :2]
        cov = 0.5 * (cov + cov.T)
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        se, cov = np.full(2, np.nan), np.full((2, 2), np.nan)
    return DiscFit(True, "", c, b, G, se, rms, it, cov, look)
