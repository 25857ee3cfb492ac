"""The tracker's per-frame arithmetic on the ball's window, compiled (numba).

Around the compiled fit (:mod:`cuespin.track.kernel`) each frame's search
and refinement spent most of their time in numpy's per-call overhead on
small windows: the iterated centroid (:func:`cuespin.track.model.moments`,
3 and 5 passes of ten numpy calls each, 0.5 ms a frame), the search's
ball-likeness score over its window and the count of foreign pixels beside
the ball.  Here each is one call, pixel by pixel, with the same arithmetic
as its numpy form (``model.moments``, the tracker's window code): the same
float32 values where numpy computes in float32, and numpy's own pairwise
sums, so the tracks are the same bit for bit (``tests/test_track_window.py``).

Imported by the tracker on first use (numba's import costs ~0.5 s, which
only tracking should pay); compiled on first use and cached on disk as
:mod:`cuespin.track.kernel` is.
"""

from __future__ import annotations

import math

import numpy as np
from numba import types
from numba.extending import intrinsic

from cuespin.track.kernel import PSF_AT, _centre_cov, _gram, _inverse, _jit, model_rows, psf_blur


@_jit()
def _block_sum(a, lo, n):
    """numpy's pairwise sum of a block of at most 128 elements."""
    if n < 8:
        res = np.zeros(1, a.dtype)[0]
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - n % 8:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@_jit()
def pairwise_sum(a):
    """numpy's ``a.sum()`` of a 1-D array, bit for bit: its pairwise
    summation (blocks of up to 128 in eight accumulators; above that, halves
    cut at a multiple of 8, each summed so and added), in ``a``'s type
    (float32 sums in float32, as numpy's).  The halving is walked with an
    explicit stack: numba's on-disk cache of a recursive function crashed."""
    n = a.shape[0]
    if n <= 128:
        return _block_sum(a, 0, n)
    # Post-order over the halving tree: nodes (lo, n, children pushed?).
    nodes = np.empty((128, 3), np.int64)
    vals = np.empty(128, a.dtype)
    top, nv = 1, 0
    nodes[0, 0], nodes[0, 1], nodes[0, 2] = 0, n, 0
    while top > 0:
        top -= 1
        lo, m, expanded = nodes[top, 0], nodes[top, 1], nodes[top, 2]
        if m <= 128:
            vals[nv] = _block_sum(a, lo, m)
            nv += 1
        elif expanded:
            nv -= 1
            vals[nv - 1] = vals[nv - 1] + vals[nv]
        else:
            m2 = m // 2
            m2 -= m2 % 8
            nodes[top, 2] = 1
            nodes[top + 1, 0], nodes[top + 1, 1], nodes[top + 1, 2] = lo + m2, m - m2, 0
            nodes[top + 2, 0], nodes[top + 2, 1], nodes[top + 2, 2] = lo, m2, 0
            top += 3
    return vals[0]


@_jit()
def centroid(D, u0, v0, cu, cv, radius, n_iter):
    """:func:`cuespin.track.model.moments`, bit for bit: the ``D``-weighted
    centroid (px) of the pixels within ``radius`` of the centre, iterated
    ``n_iter`` times from ``(cu, cv)``; unchanged when a window holds no
    signal.  numpy's sums are kept (the weights' in ``D``'s type, the
    moments' in float64, each pairwise over the whole window): the fit
    starts here, and its stopping rule (a step under 1e-3 px) turns a start
    changed by 1e-5 px into fits changed by up to 0.1 px in a frame whose
    fit is ill-conditioned (a cue touching the ball)."""
    h, w = D.shape
    r2 = radius * radius
    wgt = np.zeros(h * w, D.dtype)
    mu = np.empty(h * w)
    mv = np.empty(h * w)
    zero = wgt[0]
    for _ in range(n_iter):
        for i in range(h):
            v = float(v0 + i)
            dv2 = (v - cv) ** 2
            for j in range(w):
                u = float(u0 + j)
                p = i * w + j
                d = D[i, j] if (u - cu) ** 2 + dv2 <= r2 else zero
                wgt[p] = d
                mu[p] = d * u
                mv[p] = d * v
        tot = pairwise_sum(wgt)
        if tot <= 0:
            break
        cu, cv = pairwise_sum(mu) / tot, pairwise_sum(mv) / tot
    return cu, cv


@_jit()
def departure_centroid(P, felt, thr, u0, v0, cu, cv, radius, n_iter):
    """:func:`centroid` of ``max(|P - felt| - thr, 0)`` (the departure from
    the felt beyond the noise, in either direction), each in float32 as
    numpy computes it for float32 windows ``P`` and ``felt``."""
    h, w = P.shape
    t = np.float32(thr)
    A = np.empty((h, w), np.float32)
    for i in range(h):
        for j in range(w):
            a = np.float32(abs(np.float32(P[i, j]) - np.float32(felt[i, j])) - t)
            A[i, j] = a if a > 0 else np.float32(0.0)
    return centroid(A, u0, v0, cu, cv, radius, n_iter)


@_jit()
def foreign_count(D, u0, v0, cu, cv, bu, bv, reach, thr):
    """How many pixels of ``D`` lie farther than ``reach`` (px) from the
    blur segment (centre ``(cu, cv)``, blur ``(bu, bv)``) and depart from the
    felt by more than ``thr`` (compared in float32, as numpy compares a
    float32 window with a Python float): the pixels
    :func:`cuespin.track.tracker.foreign_pixels` groups, with
    :func:`cuespin.track.tracker.beyond_ball`'s distance."""
    h, w = D.shape
    L2 = bu * bu + bv * bv
    t = np.float32(thr)
    n = 0
    for i in range(h):
        py = float(v0 + i) - cv
        for j in range(w):
            if not abs(np.float32(D[i, j])) > t:
                continue
            px = float(u0 + j) - cu
            s = 0.0
            if L2 > 0:
                s = min(max((px * bu + py * bv) / L2, -0.5), 0.5)
            if math.hypot(px - s * bu, py - s * bv) > reach:
                n += 1
    return n


# linear_fit's Gram, scaled to a unit diagonal, is taken as singular (and
# left to numpy's SVD, which drops such directions at lstsq's rcond=1e-9)
# when a Cholesky pivot falls below this: a condition number past ~1e12,
# where the normal equations lose more than ~1e-4 of the solution; the
# markings rule's windows give ~1e2-1e4.
GRAM_PIVOT_MIN = 1e-12


@_jit()
def linear_fit(AT, y, sel):
    """Least squares of ``y`` on the columns ``AT.T`` over the pixels
    ``sel`` (bool), by the normal equations (a Cholesky solve of the
    Gram, scaled to a unit diagonal): ``np.linalg.lstsq(AT.T[sel],
    y[sel])``'s solution to rounding, in one call instead of numpy's
    copies and SVD.  Returns (theta, ok); ok False when the Gram is
    singular to ``GRAM_PIVOT_MIN`` (the caller's SVD decides then)."""
    k, n = AT.shape
    G = np.zeros((k, k))
    g = np.zeros(k)
    for p in range(n):
        if sel[p]:
            for i in range(k):
                a = AT[i, p]
                g[i] += a * y[p]
                for j in range(i + 1):
                    G[i, j] += a * AT[j, p]
    theta = np.zeros(k)
    s = np.empty(k)
    for i in range(k):
        if not G[i, i] > 0.0:
            return theta, False
        s[i] = 1.0 / math.sqrt(G[i, i])
    L = np.zeros((k, k))
    for i in range(k):  # Cholesky of diag(s) G diag(s)
        for j in range(i + 1):
            acc = G[i, j] * s[i] * s[j]
            for q in range(j):
                acc -= L[i, q] * L[j, q]
            if i == j:
                if not acc > GRAM_PIVOT_MIN:
                    return theta, False
                L[i, i] = math.sqrt(acc)
            else:
                L[i, j] = acc / L[j, j]
    z = np.empty(k)
    for i in range(k):  # L z = diag(s) g
        acc = g[i] * s[i]
        for q in range(i):
            acc -= L[i, q] * z[q]
        z[i] = acc / L[i, i]
    for i in range(k - 1, -1, -1):  # L^T x = z; theta = diag(s) x
        acc = z[i]
        for q in range(i + 1, k):
            acc -= L[q, i] * theta[q]
        theta[i] = acc / L[i, i]
    for i in range(k):
        theta[i] *= s[i]
    return theta, True


@_jit()
def _gauss_solve(M, x, n):
    """``M[:n, :n] z = x[:n]`` by Gaussian elimination with partial pivoting
    (LAPACK's gesv's rule), ``z`` into ``x``, ``M`` overwritten; False on an
    exact zero pivot (where numpy's solve raises)."""
    for c in range(n):
        piv = c
        big = abs(M[c, c])
        for i in range(c + 1, n):
            if abs(M[i, c]) > big:
                big, piv = abs(M[i, c]), i
        if big == 0.0:
            return False
        if piv != c:
            for j in range(n):
                M[c, j], M[piv, j] = M[piv, j], M[c, j]
            x[c], x[piv] = x[piv], x[c]
        for i in range(c + 1, n):
            f = M[i, c] / M[c, c]
            if f != 0.0:
                for j in range(c + 1, n):
                    M[i, j] -= f * M[c, j]
                x[i] -= f * x[c]
    for i in range(n - 1, -1, -1):
        acc = x[i]
        for j in range(i + 1, n):
            acc -= M[i, j] * x[j]
        x[i] = acc / M[i, i]
    return True


@_jit()
def _pushed_score(Jc, x, n, k, A, M, T, v):
    """One cluster's jackknifed score ``(I_k - J_g J_g^T A)^-1 J_g e_g``
    into ``v`` (``Jc`` (k, >= n) its rows, ``x`` its residuals; ``M``, ``T``
    (k, k) scratch); False on an exact zero pivot."""
    for q in range(k):
        acc = 0.0
        for i in range(n):
            acc += Jc[q, i] * x[i]
        v[q] = acc
    for q in range(k):  # J_g J_g^T, in M
        for p2 in range(q + 1):
            acc = 0.0
            for i in range(n):
                acc += Jc[q, i] * Jc[p2, i]
            M[q, p2] = acc
            M[p2, q] = acc
    for q in range(k):  # I - (J_g J_g^T) A
        for j in range(k):
            acc = 0.0
            for p2 in range(k):
                acc += M[q, p2] * A[p2, j]
            T[q, j] = (1.0 if q == j else 0.0) - acc
    return _gauss_solve(T, v, k)


@_jit()
def cluster_meat(JT, e, h, w, B, A):
    """The jackknife's meat over square clusters (CR3): for each ``B`` x
    ``B`` cluster of a ``h`` x ``w`` window (row-major; the last row and
    column of clusters cut at the window's edge), the cluster's residuals
    ``e_g`` as had it been left out, ``(I - H_gg)^-1 e_g`` with ``H_gg =
    J_g^T A J_g``, its score ``S_g = J_g (I - H_gg)^-1 e_g`` and the sum of
    ``S_g S_g^T``.  ``JT`` (k, h*w): the Jacobian's rows, ``e`` (h*w,) the
    residuals (both zero at pixels left out), ``A`` = ``(JT JT^T)^-1``.
    :func:`cuespin.track.model._jackknife_cov`'s numpy form (einsum and
    batched solves over zero-padded clusters) to rounding, in one call.
    Returns (meat, ok); ok False when some ``I - H_gg`` is singular (an
    exact zero pivot, where numpy's solve raises).

    A cluster of more pixels than parameters (``n`` > ``k``: 3 x 3 blocks
    and six or eight parameters) takes the push-through identity's form,
    ``J_g (I_n - J_g^T A J_g)^-1 e_g = (I_k - J_g J_g^T A)^-1 J_g e_g``: a
    ``k`` x ``k`` solve instead of ``n`` x ``n`` (the same to rounding; its
    determinant is the same, Sylvester's: 65 -> 34 us a 17 x 17 window,
    branch speed15)."""
    k = JT.shape[0]
    nb = B * B
    meat = np.zeros((k, k))
    Jc = np.empty((k, nb))
    AJ = np.empty((k, nb))
    M = np.empty((nb, nb))
    x = np.empty(nb)
    S = np.empty(k)
    Mk = np.empty((k, k))
    Tk = np.empty((k, k))
    v = np.empty(k)
    for gi in range(0, h, B):
        for gj in range(0, w, B):
            n = 0
            for a in range(gi, min(gi + B, h)):
                for b in range(gj, min(gj + B, w)):
                    p = a * w + b
                    for q in range(k):
                        Jc[q, n] = JT[q, p]
                    x[n] = e[p]
                    n += 1
            if n > k:
                if not _pushed_score(Jc, x, n, k, A, Mk, Tk, v):
                    return meat, False
                for q in range(k):
                    for p2 in range(k):
                        meat[q, p2] += v[q] * v[p2]
                continue
            for q in range(k):  # A J_g
                for i in range(n):
                    acc = 0.0
                    for p2 in range(k):
                        acc += A[q, p2] * Jc[p2, i]
                    AJ[q, i] = acc
            for i in range(n):  # I - J_g^T A J_g
                for j in range(n):
                    acc = 0.0
                    for q in range(k):
                        acc += Jc[q, i] * AJ[q, j]
                    M[i, j] = (1.0 if i == j else 0.0) - acc
            if not _gauss_solve(M, x, n):
                return meat, False
            for q in range(k):
                acc = 0.0
                for i in range(n):
                    acc += Jc[q, i] * x[i]
                S[q] = acc
            for q in range(k):
                for p2 in range(k):
                    meat[q, p2] += S[q] * S[p2]
    return meat, True


@_jit()
def jackknife_cov(y, felt, use, c0, c1, b0, b1, G, r, kind, geo, u0, v0, taus, shade, has_shade, blur_rows, B):
    """:func:`cuespin.track.model._jackknife_cov`'s arithmetic in one call:
    the model's rows at the fit (:func:`cuespin.track.kernel.model_rows`,
    the same call its numpy glue made), the residuals and rows on the
    pixels ``use`` (0/1, h*w), ``A = (J J^T)^-1`` (the kernel's Gram and
    Gauss-Jordan in place of BLAS's product and LAPACK's inverse: the same
    to rounding), the meat (:func:`cluster_meat`) and the centre's block of
    ``A meat A``, symmetrised.  Its numpy glue was ~0.15 s a 1,000 frames of
    the tracker's main thread (eleven small calls a fit, branch speed15).
    Returns (cov (2, 2), ok); ok False where the numpy form kept the fit's
    own sandwich: a singular ``J J^T`` or ``I - H_gg``, or a covariance not
    finite and positive definite."""
    h, w = felt.shape
    npx = h * w
    k = (5 if blur_rows else 3) + (3 if has_shade else 0)
    m = np.empty(npx)
    JT = np.empty((k, npx))
    cov = np.zeros((2, 2))
    model_rows(c0, c1, b0, b1, G, felt, r, kind, geo, u0, v0, taus, shade, has_shade, blur_rows, m, JT)
    yf = y.ravel()
    ff = felt.ravel()
    e = np.empty(npx)
    for p in range(npx):
        e[p] = (yf[p] - ff[p] - m[p]) * use[p]
    for a in range(k):
        for p in range(npx):
            JT[a, p] *= use[p]
    invertible, A = _inverse(_gram(JT, e, False))
    if not invertible:
        return cov, False
    meat, solved = cluster_meat(JT, e, h, w, B, A)
    if not solved:
        return cov, False
    V = _centre_cov(A, meat)
    cov[0, 0], cov[1, 1] = V[0, 0], V[1, 1]
    cov[0, 1] = cov[1, 0] = 0.5 * (V[0, 1] + V[1, 0])
    for a in range(2):
        for b in range(2):
            if not np.isfinite(cov[a, b]):
                return cov, False
    # Both eigenvalues of the symmetric 2 x 2 positive (numpy's eigvalsh > 0).
    if not (cov[0, 0] > 0.0 and cov[0, 0] * cov[1, 1] - cov[0, 1] * cov[0, 1] > 0.0):
        return cov, False
    return cov, True


@_jit()
def felt_shift(fo, fn, valid, has_valid, c0, c1, b0, b1, G, r, kind, geo, u0, v0, taus, shade, has_shade,
               blur_rows, rcond):
    """:func:`cuespin.track.model.refit_shift`'s arithmetic on one window
    (pixels, or blocks' means) in one call: the model's rows at the fit
    (:func:`cuespin.track.kernel.model_rows`, the calls its numpy form
    made), the old and new felts' Jacobians, their products and the least
    squares (numba's ``lstsq``: LAPACK's gelsd, as numpy's, with the same
    ``rcond``), the same to rounding.  Its numpy glue was ~0.1 s a 1,000
    frames of the main thread (branch speed15).  ``fo``, ``fn`` (h, w) the
    old and new felts, ``valid`` (h*w, 0/1) the pixels the fit used (read
    when ``has_valid``), ``shade`` the fit's look (read when
    ``has_shade``).  Returns the centre's change (2,)."""
    h, w = fo.shape
    npx = h * w
    iG = 4 if blur_rows else 2
    zero = np.zeros((h, w))
    D = np.empty((iG + 1, npx))
    m = np.empty(npx)
    # The rows before the level's are linear in the felt (the disc's at
    # level 1 on zero felt times G - felt): one evaluation serves both.
    model_rows(c0, c1, b0, b1, 1.0, zero, r, kind, geo, u0, v0, taus, shade, False, blur_rows, m, D)
    fof = fo.ravel()
    fnf = fn.ravel()
    df = np.empty(npx)
    kept = np.empty(npx)
    for p in range(npx):
        df[p] = fnf[p] - fof[p]
        kept[p] = df[p] * (1.0 - D[iG, p])
    if not has_shade:
        k = iG + 1
        Jo = D.copy()
        Jn = D
        for a in range(iG):
            for p in range(npx):
                Jo[a, p] *= G - fof[p]
                Jn[a, p] *= G - fnf[p]
    else:
        k = iG + 4
        Jo = np.empty((k, npx))
        model_rows(c0, c1, b0, b1, G, fo, r, kind, geo, u0, v0, taus, shade, True, blur_rows, m, Jo)
        Jn = Jo.copy()
        moved = np.empty((iG, npx))
        for a in range(iG):
            for p in range(npx):
                moved[a, p] = D[a, p] * df[p]
        if shade.shape[0] > PSF_AT and shade[PSF_AT] > 0.0:
            # The lit sphere's model is seen through the lens: so is the
            # felt's share of it.
            psf_blur(moved.reshape(iG, h, w), shade[PSF_AT])
            seen = np.empty(npx)
            for p in range(npx):
                seen[p] = df[p] * D[iG, p]
            psf_blur(seen.reshape(1, h, w), shade[PSF_AT])
            for p in range(npx):
                kept[p] = df[p] - seen[p]
        for a in range(iG):
            for p in range(npx):
                Jn[a, p] -= moved[a, p]
    if has_valid:
        for a in range(k):
            for p in range(npx):
                Jo[a, p] *= valid[p]
    M = np.empty((k, k))
    v = np.empty(k)
    for a in range(k):
        for q in range(k):
            acc = 0.0
            for p in range(npx):
                acc += Jo[a, p] * Jn[q, p]
            M[a, q] = acc
        acc = 0.0
        for p in range(npx):
            acc += Jo[a, p] * kept[p]
        v[a] = acc
    x = np.linalg.lstsq(M, v, rcond)[0]
    out = np.empty(2)
    out[0], out[1] = -x[0], -x[1]
    return out


@_jit()
def block_means(x, a, b, n, m, bx, by):
    """The means (float64) of the ``n`` x ``m`` whole ``bx`` x ``by``
    blocks (width x height) of ``x`` from row ``b``, column ``a``:
    :func:`cuespin.track.model.block_patch`'s ``x.reshape(n, by, m,
    bx).mean(axis=(1, 3), dtype=np.float64)`` in one call instead of
    numpy's ~0.1 ms of reductions: bit for bit wherever a block's sum is
    exact in float64, whatever the order (float32 or uint8 levels whose
    lowest bits lie within 53 of the largest's highest: a window's levels,
    0-255 with float32's 24 bits, unless one is a nonzero level under
    ~1e-6), and dividing by a power of two is exact; otherwise within an
    ulp of it."""
    out = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            acc = 0.0
            for p in range(b + i * by, b + (i + 1) * by):
                for q in range(a + j * bx, a + (j + 1) * bx):
                    acc += float(x[p, q])
            out[i, j] = acc / (bx * by)
    return out


@_jit()
def block_all(x, a, b, n, m, bx, by):
    """Whether every pixel of each whole block is True (``block_means``'
    blocks): ``block_patch``'s ``x.all(axis=(1, 3))``."""
    out = np.ones((n, m), np.bool_)
    for i in range(n):
        for j in range(m):
            for p in range(b + i * by, b + (i + 1) * by):
                for q in range(a + j * bx, a + (j + 1) * bx):
                    if not x[p, q]:
                        out[i, j] = False
    return out


@_jit()
def hidden_pixels(partial, hidden, frame, P, has_P, reference, tolerance, u0, v0, u1, v1, cu, cv, radius):
    """:meth:`cuespin.track.background.FeltAccumulator.add_frame`'s window,
    in one pass: the pixels of rows ``v0:v1``, columns ``u0:u1`` within
    ``radius`` of ``(cu, cv)`` (px), and with ``has_P`` those whose
    projected level ``P`` (the window's, float32) departs from
    ``reference`` (the frame's felt, float32) by more than ``tolerance``
    (compared in float32, as numpy compares a float32 window with a Python
    float), have their frame's levels taken back out of the 16-bit sum
    ``partial`` and count once more in ``hidden``.  ``frame`` and
    ``partial`` (h, w, c).  The same pixels and sums as numpy's masks,
    ``nonzero`` and fancy indexing (the disc's squares in float64 as
    ``FeltAccumulator._disc`` takes them)."""
    r2 = radius * radius
    t = np.float32(tolerance)
    nc = frame.shape[2]
    for i in range(v1 - v0):
        v = v0 + i
        dv = float(v) - cv
        dv2 = dv * dv
        for j in range(u1 - u0):
            u = u0 + j
            du = float(u) - cu
            out = du * du + dv2 <= r2
            if not out and has_P:
                out = abs(np.float32(P[i, j]) - np.float32(reference[v, u])) > t
            if out:
                for c in range(nc):
                    partial[v, u, c] -= frame[v, u, c]
                hidden[v, u] += 1


@_jit()
def felt_add(total, count, patch, exclude, has_exclude, reference, has_ref, tolerance, u0, v0, cu, cv, radius):
    """:meth:`cuespin.track.background.FeltAccumulator.add` in one pass:
    the window ``patch`` (float32 (h, w), top-left pixel ``(u0, v0)``)
    added to the running sums ``total`` (float32) and ``count`` (int32)
    at its pixels beyond ``radius`` of ``(cu, cv)`` (px; the disc's squares
    in float64 as ``FeltAccumulator._disc`` takes them), not ``exclude``d
    (with ``has_exclude``) and, with ``has_ref``, within ``tolerance`` of
    ``reference`` (the frame's felt, float32): ``|patch - reference|`` in
    float32 compared in float64 with ``tolerance`` already rounded to the
    dtype numpy compares in (a float32 value is exact in float64).  The
    pixels left out add 0 to ``total`` as ``np.where(felt, patch, 0)``
    does; the same sums, in place of numpy's ~10 calls a frame (~40 us).
    """
    r2 = radius * radius
    for i in range(patch.shape[0]):
        v = v0 + i
        dv = float(v) - cv
        dv2 = dv * dv
        for j in range(patch.shape[1]):
            u = u0 + j
            du = float(u) - cu
            felt = not (du * du + dv2 <= r2)
            if felt and has_exclude and exclude[i, j]:
                felt = False
            if felt and has_ref and not (float(abs(patch[i, j] - reference[v, u])) <= tolerance):
                felt = False
            if felt:
                total[v, u] += patch[i, j]
                count[v, u] += 1
            else:
                total[v, u] += np.float32(0.0)


# The markings rule's residual ``y - A theta`` here and numpy's (BLAS's
# dgemv, its own order and fused products) differ by at most 2 gamma_4
# sum |a_i theta_i| plus the subtraction's rounding, gamma_4 = 4 u / (1 - 4 u),
# u = 2^-53: under 1e-15 of |y| + sum |a_i theta_i|.  A pixel whose
# residual lies within ten times that of the threshold could be judged
# otherwise by numpy: then numpy's form judges the window
# (:func:`marks_beyond`).
RESIDUAL_BAND = 1e-14


@_jit()
def marks_beyond(patch, felt, m0, JT, use, inner, thresh):
    """The markings rule's two linear fits (``tracker.marking_pixels``):
    ``y = patch - felt - m0`` (float64), the look's four rows ``JT[2:6]``
    fitted over ``use`` (:func:`linear_fit`), the ``inner`` pixels whose
    residual departs by more than ``thresh``, fitted again without them.
    Returns (bad (bool, h*w), its count, ok); ok False when numpy's form
    must decide (a singular Gram, its SVD; or a residual within
    ``RESIDUAL_BAND`` of the threshold, where BLAS's product may round
    to the other side): otherwise the same pixels as numpy's, in one
    call for its ~15."""
    h, w = felt.shape
    n = h * w
    y = np.empty(n)
    for i in range(h):
        for j in range(w):
            y[i * w + j] = np.float64(patch[i, j]) - np.float64(felt[i, j]) - m0[i, j]
    bad = np.zeros(n, np.bool_)
    sel = use.copy()
    count = 0
    A = JT[2:6]
    for _ in range(2):
        theta, ok = linear_fit(A, y, sel)
        if not ok:
            return bad, 0, False
        count = 0
        for p in range(n):
            if inner[p]:
                s = A[0, p] * theta[0] + A[1, p] * theta[1] + A[2, p] * theta[2] + A[3, p] * theta[3]
                size = abs(A[0, p] * theta[0]) + abs(A[1, p] * theta[1]) + abs(A[2, p] * theta[2]) \
                    + abs(A[3, p] * theta[3])
                e = abs(y[p] - s)
                if not abs(e - thresh) > RESIDUAL_BAND * (abs(y[p]) + size):
                    return bad, 0, False
                bad[p] = e > thresh
                count += bad[p]
            else:
                bad[p] = False
        if count == 0:
            break
        for p in range(n):
            sel[p] = use[p] and not bad[p]
    return bad, count, True


@_jit()
def add_levels(total, frame):
    """``total += frame`` for a 16-bit sum and an 8-bit frame, both 1-D
    (a frame's and its sum's C-ordered levels: ``reshape(-1)``): numpy's
    mixed-type ``np.add`` casts the frame in buffered chunks (0.66-0.70 ms
    a 1280 x 640 BGR frame against 0.49 here); whole numbers, the same
    sums.  One flat loop: the (h, w, 3) loop it replaces was not
    vectorised (its inner loop of 3), 2.9-3.0 ms a frame (speed10,
    ``/tmp/speed10/mb_al.py``)."""
    for i in range(frame.shape[0]):
        total[i] += frame[i]


@intrinsic
def _fma32(typingctx, a, b, c):
    """``a * b + c`` in float32 rounded once (LLVM's fma), as OpenBLAS's
    compiled kernels contract a product and a sum."""
    sig = types.float32(types.float32, types.float32, types.float32)

    def codegen(context, builder, signature, args):
        return builder.fma(*args)
    return sig, codegen


@_jit()
def project_bgr(roi, w, off):
    """:class:`cuespin.track.colour.Projection` of a BGR window ``roi``
    (uint8, (h, n, 3), n >= 2): ``roi.astype(np.float32) @ w + off`` in
    float32, bit for bit.  numpy hands each row to OpenBLAS's sgemv, whose
    kernel on this machine (SkylakeX, the set OpenBLAS picks at run time;
    numpy's build string says Haswell) (``sgemv_t``, 3 rows) takes the row's pixels in blocks:
    of 8 as ``fma(b2, w2, fma(b1, w1, b0 w0))``, one of 4 and the odd last
    pixel as ``fma(b2, w2, fma(b0, w0, b1 w1))``, a pair as ``(b0 w0 + b1
    w1) + b2 w2`` (found by comparing every width 2-129 and 640, 1280 on
    random levels and weights; a width of 1 goes another way and stays
    numpy's).  One pass, no float32 copy of the window."""
    h, n = roi.shape[0], roi.shape[1]
    out = np.empty((h, n), np.float32)
    w0, w1, w2 = np.float32(w[0]), np.float32(w[1]), np.float32(w[2])
    e8, e4, e2 = n & -8, n & -4, n & -2
    for y in range(h):
        for x in range(e8):  # one loop a block kind: no branch in the loop
            b0, b1, b2 = np.float32(roi[y, x, 0]), np.float32(roi[y, x, 1]), np.float32(roi[y, x, 2])
            out[y, x] = _fma32(b2, w2, _fma32(b1, w1, b0 * w0)) + off
        for x in range(e8, e4):
            b0, b1, b2 = np.float32(roi[y, x, 0]), np.float32(roi[y, x, 1]), np.float32(roi[y, x, 2])
            out[y, x] = _fma32(b2, w2, _fma32(b0, w0, b1 * w1)) + off
        for x in range(e4, e2):
            b0, b1, b2 = np.float32(roi[y, x, 0]), np.float32(roi[y, x, 1]), np.float32(roi[y, x, 2])
            out[y, x] = ((b0 * w0 + b1 * w1) + b2 * w2) + off
        for x in range(e2, n):
            b0, b1, b2 = np.float32(roi[y, x, 0]), np.float32(roi[y, x, 1]), np.float32(roi[y, x, 2])
            out[y, x] = _fma32(b2, w2, _fma32(b0, w0, b1 * w1)) + off
    return out


@_jit(inline="always")
def _reflect101(i, n):
    """OpenCV's ``BORDER_REFLECT_101`` index (``borderInterpolate``)."""
    if n == 1:
        return 0
    while i < 0 or i >= n:
        i = -i if i < 0 else 2 * n - 2 - i
    return i


@_jit()
def peak_score(P, felt, pol, cap, k, K, r0, r1, c0, c1):
    """The tracker's search score (``Tracker._peak``) at rows ``r0:r1``,
    columns ``c0:c1`` of a window: ``box_score(clip(pol (P - felt), -cap,
    cap), k, K)`` cut there, float32, bit for bit.  ``P`` the window's
    projected levels, ``felt`` the felt's there (float32 (h, w)).
    ``cv2.blur`` and ``cv2.boxFilter`` sum a float32 image in float64
    (OpenCV's running ``RowSum`` and ``ColumnSum`` of double; IPP's on the
    ``blur``, measured equal), where a box's at most K^2 levels of at most
    ``cap`` add exactly in any order while each is a whole multiple of
    2^-37 (every level of magnitude 2^-14 or more is): the same float64
    sums here (running, in another order), the inner one scaled by ``1 /
    (k k)`` in float64 as OpenCV scales it, each rounded to float32 once;
    borders reflected (``BORDER_REFLECT_101``) at the window's edges.  Box
    sums are made only for the rows and columns the cut needs."""
    h, w = P.shape
    a, A = k // 2, K // 2
    D = np.empty((h, w), np.float32)
    for y in range(h):
        for x in range(w):
            d = np.float32(pol * (P[y, x] - felt[y, x]))
            D[y, x] = min(max(d, -cap), cap)
    nr, nc = (r1 - r0) + 2 * A, c1 - c0  # the rows the cut's boxes reach
    rk = np.empty((nr, nc))
    rK = np.empty((nr, nc))
    for i in range(nr):
        y = _reflect101(r0 - A + i, h)
        sk = 0.0
        for t in range(c0 - a, c0 - a + k):
            sk += np.float64(D[y, _reflect101(t, w)])
        sK = 0.0
        for t in range(c0 - A, c0 - A + K):
            sK += np.float64(D[y, _reflect101(t, w)])
        rk[i, 0], rK[i, 0] = sk, sK
        for j in range(1, nc):
            x = c0 + j
            sk += np.float64(D[y, _reflect101(x - a + k - 1, w)]) - np.float64(D[y, _reflect101(x - a - 1, w)])
            sK += np.float64(D[y, _reflect101(x - A + K - 1, w)]) - np.float64(D[y, _reflect101(x - A - 1, w)])
            rk[i, j], rK[i, j] = sk, sK
    out = np.empty((r1 - r0, nc), np.float32)
    scale = 1.0 / (k * k)
    kk, ring = np.float32(k * k), np.float32(K * K - k * k)
    for j in range(nc):
        sk = 0.0
        for t in range(A - a, A - a + k):
            sk += rk[t, j]
        sK = 0.0
        for t in range(K):
            sK += rK[t, j]
        for i in range(r1 - r0):
            if i > 0:
                sk += rk[i + A - a + k - 1, j] - rk[i + A - a - 1, j]
                sK += rK[i + K - 1, j] - rK[i - 1, j]
            inner = np.float32(sk * scale)
            out[i, j] = inner - (np.float32(sK) - inner * kk) / ring
    return out


def warm_up() -> None:
    """Load (after an install, compile) each kernel for the arrays the
    tracker passes: float32 windows, contiguous or cut from the felt."""
    D = np.ones((9, 9), np.float32)
    felt = np.zeros((12, 12), np.float32)[1:10, 1:10]
    centroid(D, 0, 0, 4.0, 4.0, 3.0, 3)
    departure_centroid(D, felt, 1.0, 0, 0, 4.0, 4.0, 3.0, 5)
    foreign_count(D, 0, 0, 4.0, 4.0, 0.0, 0.0, 3.0, 1.0)
    AT = np.ones((6, 9))
    linear_fit(AT[2:6], np.ones(9), np.ones(9, bool))
    cluster_meat(AT * 0.1, np.ones(9), 3, 3, 3, np.eye(6))
    y = np.full((3, 3), 2.0)
    jackknife_cov(y, y - 1.0, np.ones(9), 1.0, 1.0, 0.0, 0.0, 3.0, 1.0, 0, np.ones(1), 0, 0, np.zeros(1),
                  np.zeros(3), True, False, 3)
    felt_shift(y, y - 1.0, np.ones(9), True, 1.0, 1.0, 0.0, 0.0, 3.0, 1.0, 0, np.ones(1), 0, 0, np.zeros(1),
               np.zeros(3), True, False, 1e-9)
    block_means(D, 0, 0, 4, 4, 2, 2)
    block_means(felt, 0, 0, 4, 4, 2, 2)
    block_all(np.ones((9, 9), bool), 0, 0, 4, 4, 2, 2)
    felt_add(np.zeros((12, 12), np.float32), np.zeros((12, 12), np.int32), D, np.zeros((9, 9), np.bool_), True,
             np.zeros((12, 12), np.float32), True, 1.0, 1, 1, 4.0, 4.0, 3.0)  # the whole felt: contiguous
    hidden_pixels(np.zeros((9, 9, 3), np.uint16), np.zeros((9, 9), np.int32), np.zeros((9, 9, 3), np.uint8), D, True,
                  D, 1.0, 0, 0, 9, 9, 4.0, 4.0, 3.0)
    frame = np.zeros((12, 12, 3), np.uint8)
    P = project_bgr(frame[1:10, 1:10], np.ones(3, np.float32), np.float32(0.0))
    project_bgr(frame, np.ones(3, np.float32), np.float32(0.0))
    peak_score(P, felt, 1, np.float32(1.0), 3, 7, 2, 7, 2, 7)
    add_levels(np.zeros(9, np.uint16), np.zeros(9, np.uint8))
    marks_beyond(D, felt, np.zeros((9, 9)), np.ones((6, 81)), np.ones(81, np.bool_), np.ones(81, np.bool_), 1.0)
    peak_score(D, felt, 1, np.float32(1.0), 3, 7, 2, 7, 2, 7)


__all__ = ["add_levels", "block_all", "block_means", "centroid", "cluster_meat", "departure_centroid", "foreign_count",
           "felt_shift", "hidden_pixels", "jackknife_cov", "linear_fit", "marks_beyond", "peak_score", "project_bgr",
           "warm_up"]



@_jit()
def yuv420_bgr(y, u, v, v0, u0, out, fy, bu, guv, rv, clip):
    """BGR (``out``, (h, w, 3) uint8) of rows ``v0:v0 + h``, columns
    ``u0:u0 + w`` of a 4:2:0 frame's planes ``y`` (rows, stride), ``u``,
    ``v`` (their half-size rows) by FFmpeg swscale's fixed-point arithmetic
    (:func:`cuespin.track.reader.swscale_terms`): each channel the luma's
    term ``fy[Y]`` plus its chroma's (``bu[U]``, ``guv[U, V]``, ``rv[V]``),
    saturated to 0-255 by ``clip`` (indexed by the sum + 512); pixel (r, c)
    takes the chroma sample (r // 2, c // 2), as swscale's unscaled
    converter does.  Each row's chroma terms are looked up once per chroma
    row (2.9 -> 2.4 ms a 1280 x 640 frame)."""
    h, w = out.shape[0], out.shape[1]
    tb = np.empty(w, np.int32)
    tg = np.empty(w, np.int32)
    tr = np.empty(w, np.int32)
    for i in range(h):
        r = v0 + i
        if i == 0 or (r & 1) == 0:
            ur = u[r >> 1]
            vr = v[r >> 1]
            for j in range(w):
                c = (u0 + j) >> 1
                U = ur[c]
                V = vr[c]
                tb[j] = bu[U] + 512
                tg[j] = guv[U, V] + 512
                tr[j] = rv[V] + 512
        yr = y[r]
        o = out[i]
        for j in range(w):
            L = fy[yr[u0 + j]]
            o[j, 0] = clip[L + tb[j]]
            o[j, 1] = clip[L + tg[j]]
            o[j, 2] = clip[L + tr[j]]
    return out
