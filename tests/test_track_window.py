"""The tracker's compiled window arithmetic (track/window.py) against its numpy forms.

Each kernel keeps numpy's arithmetic, sums included (numpy's pairwise
summation, float32 sums in float32), so the agreement asked for is exact:
the fit starts from the centroid, and its stopping rule turned a start
moved by 1e-5 px (a float64 sum of the weights in place of numpy's float32
one) into fits moved by up to 0.1 px in ill-conditioned frames.
"""

import cv2
import numpy as np
import pytest

from cuespin.track import window
from cuespin.track.colour import departure_box_means
from cuespin.track.model import moments
from cuespin.track.tracker import FOREIGN_GAP_PX, OUTLIER_SIGMAS, beyond_ball


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_pairwise_sum_is_numpys_bit_for_bit(dtype):
    rng = np.random.default_rng(1)
    # Lengths across numpy's cases: under 8, one block (<= 128), halved blocks.
    for n in list(range(1, 140)) + [1369, 3969, 8191, 8193, 20000]:
        a = (rng.normal(0, 100, n) * (rng.random(n) < 0.7)).astype(dtype)
        assert window.pairwise_sum(a) == a.sum(), n


def random_window(rng, dtype=np.float32):
    h, w = rng.integers(5, 90, 2)
    D = rng.normal(5, 50, (h, w)).astype(dtype)
    u0, v0 = (int(x) for x in rng.integers(0, 1000, 2))
    c0 = (u0 + w / 2 + rng.normal(0, 3), v0 + h / 2 + rng.normal(0, 3))
    return D, u0, v0, c0, float(rng.uniform(3, min(h, w) / 2 + 3))


def test_centroid_is_moments_bit_for_bit():
    rng = np.random.default_rng(2)
    for i in range(300):
        D, u0, v0, c0, r = random_window(rng, np.float32 if i % 2 else np.float64)
        n_iter = int(rng.integers(1, 6))
        got = window.centroid(D, u0, v0, float(c0[0]), float(c0[1]), r, n_iter)
        assert np.array_equal(got, moments(D, u0, v0, c0, r, n_iter))
    # A window without signal leaves the start as it was.
    assert window.centroid(-np.ones((9, 9), np.float32), 0, 0, 4.2, 3.9, 3.0, 3) == (4.2, 3.9)


def test_departure_centroid_is_the_numpy_form():
    rng = np.random.default_rng(3)
    for _ in range(200):
        P, u0, v0, c0, r = random_window(rng)
        felt = np.ascontiguousarray(rng.normal(0, 40, (P.shape[0] + 4, P.shape[1] + 2)).astype(np.float32))
        felt = felt[2:-2, 1:-1]  # cut from a larger image, as the tracker's felt is
        thr = OUTLIER_SIGMAS * float(rng.uniform(0.5, 6))
        A = np.clip(np.abs(P - felt) - thr, 0, None)
        got = window.departure_centroid(P, felt, thr, u0, v0, float(c0[0]), float(c0[1]), r, 5)
        assert np.array_equal(got, moments(A, u0, v0, c0, r, n_iter=5))


def test_foreign_count_is_beyond_ball_and_the_threshold():
    rng = np.random.default_rng(4)
    for i in range(300):
        D, u0, v0, c0, _ = random_window(rng)
        b = rng.normal(0, 6, 2) if i % 3 else np.zeros(2)
        r_out, thr = float(rng.uniform(5, 20)), float(rng.uniform(5, 80))
        want = int((beyond_ball(D.shape, u0, v0, c0, b, r_out) & (np.abs(D) > thr)).sum())
        got = window.foreign_count(D, u0, v0, float(c0[0]), float(c0[1]), float(b[0]), float(b[1]),
                                   r_out + FOREIGN_GAP_PX, thr)
        assert got == want


def test_departure_box_means_per_part_are_the_whole_boxs():
    """Two moving regions far apart, one at the image's edge: the box means
    per connected part equal those over the bounding box of both, bit for
    bit (whole-level departures; an even count of samples gives halves)."""
    rng = np.random.default_rng(5)
    H, W, k = 120, 200, 7
    on = np.zeros((H, W), np.uint8)
    on[5:30, 10:40] = 1
    on[80:120, 150:200] = 1  # touches the bottom and right edges
    ys, xs = np.nonzero(cv2.erode(on, np.ones((k, k), np.uint8), borderValue=1))
    near = np.zeros((H, W), np.uint8)
    near[ys, xs] = 1
    near = cv2.dilate(near, np.ones((k, k), np.uint8))  # as colour.ball_direction makes it
    for n in (9, 8):
        samples = rng.integers(0, 256, (n, H, W, 3), dtype=np.uint8)
        X = samples.astype(np.float32)
        D = (X - np.median(X, axis=0)) * near[..., None].astype(bool)
        want = np.stack([cv2.blur(d, (k, k)) for d in D])[:, ys, xs]
        assert np.array_equal(departure_box_means(samples, near, ys, xs, k), want)


def test_moved_boxes_from_integer_sums_are_the_float_blurs():
    """moved_boxes' box means from integer sums: the extremes and span of
    cv2.blur's float32 means, bit for bit."""
    from cuespin.track.colour import moved_boxes
    from cuespin.track.background import box_size, spread_threshold

    rng = np.random.default_rng(6)
    samples = rng.integers(0, 256, (5, 90, 130, 3), dtype=np.uint8)
    samples[:, 20:40, 30:60] = rng.integers(0, 40, (5, 1, 1, 3), dtype=np.uint8)  # something moved
    r, sd = 6.0, np.array([2.0, 3.0, 4.0])
    k = box_size(r)
    b = np.stack([cv2.blur(s.astype(np.float32), (k, k)) for s in samples])
    span = b.max(axis=0) - b.min(axis=0)
    noise_thr = 7.5 * np.maximum(sd, 0.5) / k + 1.0
    want = np.any(span > [spread_threshold(span[..., i], noise_thr[i]) for i in range(3)], axis=-1)
    assert np.array_equal(moved_boxes(samples, r, sd), want)


def test_sample_medians_are_numpys_bit_for_bit():
    """median_u8 (a sort network over the samples) and median_counts (from
    the values' counts): numpy's medians bit for bit, odd and even counts."""
    from cuespin.track.colour import median_counts, median_u8, noise_covariance

    rng = np.random.default_rng(7)
    for n in (1, 2, 3, 8, 9, 10):
        X = rng.integers(0, 256, (n, 31, 17, 3), dtype=np.uint8)
        X[:, :5] = 255  # ties and the extremes
        assert np.array_equal(median_u8(X), np.median(X.astype(np.float32), axis=0))
    for n in (1, 2, 1001, 1002):
        x = rng.integers(0, 256, (n, 3), dtype=np.uint8)
        assert np.array_equal(median_counts(x), np.median(x, axis=0))
        # 8 bits are counted by OpenCV's histogram, any other dtype by bincount; a strided view too
        assert np.array_equal(median_counts(x.astype(np.int32)), np.median(x, axis=0))
        assert np.array_equal(median_counts(x[::2, ::-1]), np.median(x[::2, ::-1], axis=0))
    # noise_covariance's robust centre and spread from counts: the numpy form's
    a = rng.integers(0, 256, (64, 96, 3), dtype=np.uint8)
    b = np.clip(a + rng.normal(0, 4, a.shape), 0, 255).astype(np.uint8)
    b[10:30, 20:50] = 0  # something moved
    d = (a.astype(np.float32) - b.astype(np.float32)).reshape(-1, 3)
    med = np.median(d, axis=0)
    mad = 1.4826 * np.median(np.abs(d - med), axis=0)
    d = d[np.all(np.abs(d - med) <= np.maximum(5 * mad, 1.5), axis=1)].astype(np.float64)
    cov = (d.T @ d) / len(d) / 2.0
    want = cov + (1 / 12 + 0.05 * np.trace(cov) / 3.0) * np.eye(3)
    assert np.array_equal(noise_covariance(a, b), want)


def test_linear_fit_is_lstsqs_solution():
    # The markings rule's fit (level and the look's three columns) by the
    # normal equations: numpy's SVD solution to rounding (the rule compares
    # residuals with a threshold of levels; 1e-9 relative is far below any).
    rng = np.random.default_rng(4)
    for _ in range(100):
        n = int(rng.integers(12, 1500))
        JT = rng.normal(0, 1, (6, n))
        JT[2] = 1.0  # the level's column
        y = rng.normal(0, 20, n)
        sel = rng.random(n) < 0.8
        theta, ok = window.linear_fit(JT[2:6], y, sel)
        ref = np.linalg.lstsq(JT[2:6].T[sel], y[sel], rcond=1e-9)[0]
        assert ok
        np.testing.assert_allclose(theta, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    # A singular Gram (two equal columns) is left to the SVD.
    JT = rng.normal(0, 1, (6, 50))
    JT[3] = JT[2]
    assert not window.linear_fit(JT[2:6], rng.normal(0, 1, 50), np.ones(50, bool))[1]


def test_label_table_is_isin():
    from cuespin.track.tracker import _members
    rng = np.random.default_rng(5)
    img = (rng.random((40, 50)) < 0.3).astype(np.uint8)
    n, labels = cv2.connectedComponents(img, connectivity=8)
    pick = rng.choice(n, size=max(n // 3, 1), replace=False)
    assert np.array_equal(_members(n, pick)[labels], np.isin(labels, pick))


def test_departure_width_tells_a_ball_from_a_cue():
    """departure_width: a ball's disc, its crescents (a ball that moved a
    third of a radius) and a cue's band (0.7 radii wide, 2 long: the cue's
    departing stretch of sample_scenes(1, 6, realistic)[0]) under noise
    sigma 6, projected on their colour: the disc and crescents at or over
    WIDE_MIN, the band under it, each by the margin the shapes' second
    moments give (disc 0.25, band (0.7)^2 / 12 + blur)."""
    from cuespin.track.colour import WIDE_MIN, departure_width

    rng = np.random.default_rng(8)
    R, H, W = 8.0, 64, 64
    yy, xx = np.mgrid[:H, :W]
    rest = np.full((4, H, W, 3), 100, np.uint8)  # the samples' median: the felt
    Li = np.eye(3) / 6.0
    zhat = np.array([[0.0, -0.6, 0.8]])
    ball = np.array([0.0, -18.0, 24.0])  # 30 levels along zhat: 5 noise sigmas a pixel
    cue = np.array([0.0, -60.0, 80.0])   # the cue departs more, as in the clip

    def frame(cover):
        f = 100.0 + cover + rng.normal(0, 6, (H, W, 3))
        return np.clip(np.rint(f), 0, 255).astype(np.uint8)

    def width(cover):
        samples = np.concatenate([frame(cover)[None], rest])
        return departure_width(samples, 0, np.array([32]), np.array([32]), zhat, int(R), Li)[0]

    disc = (np.hypot(xx - 32, yy - 32) <= R)[..., None] * ball
    moved = ((np.hypot(xx - 32 - R / 3, yy - 32) <= R).astype(float) - (np.hypot(xx - 32, yy - 32) <= R))[..., None] * ball
    band = ((np.abs(yy - 32) <= 0.35 * R) & (np.abs(xx - 32) <= R))[..., None] * cue
    # Measured (seed 8): disc 0.275, the moved crescent 0.368, the band 0.087.
    assert width(disc) >= WIDE_MIN + 0.05
    assert width(moved) >= WIDE_MIN
    assert width(band) <= WIDE_MIN - 0.05


def test_box_noise_scale_is_one_on_independent_noise():
    """box_noise_scale: ~1 where the noise is independent between pixels
    (the box mean's noise is the pixel's over k), several where it is
    shared by blocks (an 8 x 8 block's common error, as MJPG's)."""
    from cuespin.track.colour import box_noise_scale

    rng = np.random.default_rng(9)
    a = np.clip(np.rint(100 + rng.normal(0, 5, (240, 320, 3))), 0, 255).astype(np.uint8)
    b = np.clip(np.rint(100 + rng.normal(0, 5, (240, 320, 3))), 0, 255).astype(np.uint8)
    L = np.linalg.cholesky(np.eye(3) * 2 * 25 / 2 + np.eye(3) / 12)  # per-pixel covariance of one frame's noise
    assert 0.85 < box_noise_scale(a, b, 11, L) < 1.2  # measured 1.0 (its floor: the upper bound is the test)
    blocks = np.kron(rng.normal(0, 3, (30, 40, 3)), np.ones((8, 8, 1)))
    c = np.clip(np.rint(100 + rng.normal(0, 5, (240, 320, 3)) + blocks), 0, 255).astype(np.uint8)
    assert box_noise_scale(a, c, 11, L) > 2.0


def _jackknife_meat_numpy(JT, e, h, w, B, A):
    """The jackknife's meat as model._jackknife_cov computed it before
    (zero-padded clusters, einsum and batched solves)."""
    k = JT.shape[0]
    H, W = h + (-h % B), w + (-w % B)
    Jp, ep = np.zeros((k, H, W)), np.zeros((H, W))
    Jp[:, :h, :w], ep[:h, :w] = JT.reshape(k, h, w), e.reshape(h, w)
    Jg = Jp.reshape(k, H // B, B, W // B, B).transpose(1, 3, 0, 2, 4).reshape(-1, k, B * B)
    eg = ep.reshape(H // B, B, W // B, B).transpose(0, 2, 1, 3).reshape(-1, B * B)
    Hgg = np.einsum("gki,kl,glj->gij", Jg, A, Jg)
    eg = np.linalg.solve(np.eye(B * B) - Hgg, eg[..., None])[..., 0]
    S = np.einsum("gki,gi->gk", Jg, eg)
    return S.T @ S


def test_cluster_meat_is_the_padded_numpy_form():
    # Rounding only (sums in another order, elimination instead of LAPACK's
    # LU): the covariance's 1e-10 relative is far below any stated error's
    # digits (the tracks on the speed file agree to ~1e-13 relative).
    rng = np.random.default_rng(6)
    for _ in range(100):
        h, w = (int(x) for x in rng.integers(6, 26, 2))
        k = int(rng.choice([5, 6, 8]))
        B = int(rng.choice([1, 2, 3]))
        use = (rng.random(h * w) < 0.9).astype(float)
        JT = rng.normal(0, 30, (k, h * w)) * use
        e = rng.normal(0, 5, h * w) * use
        A = np.linalg.inv(JT @ JT.T)
        meat, ok = window.cluster_meat(JT, e, h, w, B, A)
        ref = _jackknife_meat_numpy(JT, e, h, w, B, A)
        assert ok
        np.testing.assert_allclose(meat, ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())


@pytest.mark.parametrize("dtype", [np.float32, np.uint8])
def test_block_means_are_numpys_bit_for_bit(dtype):
    rng = np.random.default_rng(7)
    for _ in range(200):
        h, w = (int(x) for x in rng.integers(4, 50, 2))
        big = rng.normal(100, 60, (h + 3, w + 3)).clip(0, 255).astype(dtype)
        x = big[1:1 + h, 2:2 + w]  # cut from a larger image, as the felt is
        # square (4:2:0's 2) and oblong (4:2:2's 2 x 1, 4:1:1's 4 x 1, 4:4:0's 1 x 2) blocks
        bx, by = [(2, 2), (3, 3), (2, 1), (4, 1), (1, 2)][int(rng.integers(5))]
        a, b = int(rng.integers(0, bx)), int(rng.integers(0, by))
        n, m = (h - b) // by, (w - a) // bx
        ref = x[b:b + n * by, a:a + m * bx].reshape(n, by, m, bx)
        assert np.array_equal(window.block_means(x, a, b, n, m, bx, by), ref.mean(axis=(1, 3), dtype=np.float64))
        ok = x > 20
        ref_ok = ok[b:b + n * by, a:a + m * bx].reshape(n, by, m, bx).all(axis=(1, 3))
        assert np.array_equal(window.block_all(ok, a, b, n, m, bx, by), ref_ok)


@pytest.mark.parametrize("colour", [True, False])
def test_hidden_pixels_are_add_frames_numpy_form(colour):
    from cuespin.track.background import FeltAccumulator
    from cuespin.track.colour import Projection
    rng = np.random.default_rng(8)
    shape = (60, 80, 3) if colour else (60, 80)
    proj = Projection(w=np.array([0.3, -0.5, 0.2], np.float32), offset=20.0) if colour else None
    acc, ref = FeltAccumulator(shape), FeltAccumulator(shape)
    for _ in range(30):
        frame = rng.integers(0, 256, shape, dtype=np.uint8)
        felt = (proj(frame) if colour else frame.astype(np.float32)) + rng.normal(0, 4, shape[:2]).astype(np.float32)
        centre, radius = rng.uniform(-10, 90, 2), float(rng.uniform(2, 12))
        tol, reach = float(rng.uniform(1, 8)), float(rng.uniform(0, 30))
        acc.add_frame(frame, centre, radius, felt, proj, tol, reach)
        # add_frame's numpy form
        np.add(ref._partial, frame, out=ref._partial)
        H, W = shape[:2]
        r = int(np.ceil(max(radius, reach))) + 1
        u, v = int(round(centre[0])), int(round(centre[1]))
        u0, v0, u1, v1 = max(u - r, 0), max(v - r, 0), min(u + r + 1, W), min(v + r + 1, H)
        if u1 <= u0 or v1 <= v0:
            continue
        out = ref._disc(u0, v0, v1 - v0, u1 - u0, centre, radius)
        P = proj(frame, v0, v1, u0, u1) if colour else frame[v0:v1, u0:u1]
        out |= np.abs(P - felt[v0:v1, u0:u1]) > tol
        ys, xs = np.nonzero(out)
        ref._partial[v0:v1, u0:u1][ys, xs] -= frame[v0:v1, u0:u1][ys, xs]
        ref.full_hidden[v0:v1, u0:u1] += out
        assert np.array_equal(acc._partial, ref._partial) and np.array_equal(acc.full_hidden, ref.full_hidden)


def _ball_window(rng, trial):
    """A random ball's window: (h, w, centre, radius (px), whether its
    blur is fitted, blur vector (px): every third trial)."""
    h, w = (int(x) for x in rng.integers(14, 22, 2))
    c = np.array([w / 2 + rng.uniform(-1, 1), h / 2 + rng.uniform(-1, 1)])
    fit_blur = trial % 3 == 0
    return h, w, c, rng.uniform(3.5, 5.0), fit_blur, np.array([2.5, 1.0]) if fit_blur else np.zeros(2)


def _jackknife_cov_numpy(g, y, felt, U0, V0, r, fit_blur, shade, ok):
    """model._jackknife_cov's covariance as its numpy glue computed it before
    (the model's rows, BLAS's Gram, LAPACK's inverse, cluster_meat, A meat A)."""
    from cuespin.track.model import CLUSTER_PX, SPHERE_CLUSTER_PX, _model_rows, blur_nodes

    h, w = y.shape
    m, JT = _model_rows(g.c, g.b, g.G, felt, r, U0, V0, blur_nodes(np.hypot(*g.b)), g.shade, fit_blur)
    use = np.ones((h, w)) if ok is None else np.asarray(ok, float)
    e = ((y - felt - m) * use).ravel()
    JT = JT * use.ravel()
    A = np.linalg.inv(JT @ JT.T)
    meat, solved = window.cluster_meat(JT, e, h, w, max(int(CLUSTER_PX if shade is True else SPHERE_CLUSTER_PX), 1), A)
    assert solved
    cov = (A @ meat @ A)[:2, :2]
    return 0.5 * (cov + cov.T)


@pytest.mark.parametrize("look", [False, True, "sphere"])
def test_jackknife_cov_is_the_numpy_glue(look):
    # Rounding only (the kernel's Gram and Gauss-Jordan for BLAS's product
    # and LAPACK's inverse): 1e-9 relative is far below a stated error's
    # digits; the tracks on the speed files agree to it (branch speed15).
    from cuespin.render.draw import disc_coverage
    from cuespin.track.model import SphereLook, _jackknife_cov, fit_disc

    shade = SphereLook(0.6, 0.9, 8.0) if look == "sphere" else look
    rng = np.random.default_rng(11)
    for trial in range(12):
        h, w, c, r, fit_blur, b0 = _ball_window(rng, trial)
        felt = 90.0 + rng.normal(0, 1, (h, w))
        cover = np.mean([disc_coverage(*(c + t * b0), r, 0, 0, w, h) for t in np.linspace(-0.5, 0.5, 9)], axis=0)
        y = felt + 120.0 * cover + rng.normal(0, 3, (h, w))
        ok = None if trial % 2 else rng.random((h, w)) > 0.05
        # The blur held (a fitted one need not converge on 12 random
        # streaks); the jackknife's rows then take it as fitted or not.
        g = fit_disc(y, felt, 0, 0, c, r, 200.0, b0=b0, shade=shade, valid=ok)
        assert g
        got = _jackknife_cov(g, y, felt, 0, 0, r, fit_blur, shade, ok, None)
        ref = _jackknife_cov_numpy(g, y, felt, 0, 0, r, fit_blur, shade, ok)
        np.testing.assert_allclose(got.cov, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
        np.testing.assert_allclose(got.stderr, np.sqrt(np.diag(ref)), rtol=1e-9)


def _refit_shift_numpy(felt_old, felt_new, u0, v0, c, b, G, r, fit_blur, shade=None, valid=None):
    """model.refit_shift (pixels) as its numpy form computed it before."""
    from cuespin.track import kernel
    from cuespin.track.model import _model_rows, blur_nodes

    taus = blur_nodes(np.hypot(*b))
    felt_old, felt_new = np.asarray(felt_old, np.float64), np.asarray(felt_new, np.float64)
    iG = 4 if fit_blur else 2
    _, D = _model_rows(c, b, 1.0, np.zeros_like(felt_old), r, u0, v0, taus, None, fit_blur)
    df = (felt_new - felt_old).ravel()
    cov = D[iG]
    kept = df * (1.0 - cov)
    if shade is None:
        Jo, Jn = D.copy(), D
        Jo[:iG] *= (G - felt_old).ravel()
        Jn[:iG] *= (G - felt_new).ravel()
    else:
        _, Jo = _model_rows(c, b, G, felt_old, r, u0, v0, taus, shade, fit_blur)
        Jn = Jo.copy()
        moved = D[:iG] * df
        psf = float(shade[kernel.PSF_AT]) if len(shade) > kernel.PSF_AT else 0.0
        if psf > 0:
            h, w = felt_old.shape
            moved = moved.reshape(-1, h, w)
            kernel.psf_blur(moved, psf)
            seen = (df * cov).reshape(1, h, w)
            kernel.psf_blur(seen, psf)
            moved, kept = moved.reshape(iG, -1), df - seen.ravel()
        Jn[:iG] -= moved
    if valid is not None:
        Jo = Jo * np.asarray(valid, float).reshape(1, -1)
    return -np.linalg.lstsq(Jo @ Jn.T, Jo @ kept, rcond=1e-9)[0][:2]


@pytest.mark.parametrize("look", [None, "quadratic", "sphere", "sphere_psf"])
def test_felt_shift_is_the_numpy_form(look):
    # Rounding only (sums in another order; numba's gelsd for numpy's): the
    # tracks' centres on the speed files agree to it (branch speed15).
    from cuespin.track.model import SphereLook, refit_shift

    rng = np.random.default_rng(12)
    geo = {"sphere": SphereLook(0.6, 0.9, 8.0), "sphere_psf": SphereLook(0.6, 0.9, 8.0, psf=0.8)}
    for trial in range(12):
        h, w, c, r, fit_blur, b = _ball_window(rng, trial)
        shade = None if look is None else (np.array([3.0, -2.0, 5.0]) if look == "quadratic"
                                           else np.r_[40.0, 20.0, -3.0, geo[look].geometry()])
        old = (90.0 + rng.normal(0, 1, (h, w))).astype(np.float32)
        new = old + rng.normal(0, 2, (h, w)).astype(np.float32)
        valid = None if trial % 2 else rng.random((h, w)) > 0.05
        got = refit_shift(old, new, 3, 5, c + (3, 5), b, 200.0, r, fit_blur, shade, valid=valid)
        ref = _refit_shift_numpy(old, new, 3, 5, c + (3, 5), b, 200.0, r, fit_blur, shade, valid)
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)


def _blas_core():
    """OpenBLAS's kernel set in use (numpy's scipy-openblas), or None."""
    import ctypes
    import glob
    import os
    for lib in glob.glob(os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs", "*openblas*")):
        try:
            f = ctypes.CDLL(lib).scipy_openblas_get_corename64_
        except (OSError, AttributeError):
            continue
        f.restype = ctypes.c_char_p
        return f().decode()
    return None


def test_project_bgr_is_blass_product_bit_for_bit():
    # Every width of OpenBLAS's blocks (8, 4, 2, 1 pixels) and whole rows;
    # windows cut from a frame (strided), random levels, weights, offsets.
    # The blocks' order is SkylakeX's sgemv (the kernel set OpenBLAS picks
    # on the project's machine, where it was found): bit for bit there;
    # another kernel set sums the three products in its own order, within
    # a few float32 roundings of the products' magnitude.
    from cuespin.track.colour import Projection
    exact = _blas_core() == "SkylakeX"
    rng = np.random.default_rng(11)
    frame = rng.integers(0, 256, (200, 1280, 3), dtype=np.uint8)
    for n in list(range(2, 40)) + [61, 64, 127, 640, 1280]:
        for h in (1, 23):
            w = rng.normal(0, 0.4, 3).astype(np.float32)
            off = float(rng.normal(0, 60))
            v0, u0 = int(rng.integers(0, 200 - h)), int(rng.integers(0, 1280 - n + 1))
            roi = frame[v0:v0 + h, u0:u0 + n]
            ref = (roi.astype(np.float32) @ w + np.float32(off)).astype(np.float32)
            size = roi.astype(np.float64) @ np.abs(w.astype(np.float64)) + abs(off)
            for got in (window.project_bgr(roi, w, np.float32(off)),
                        Projection(w=w, offset=off)(frame, v0, v0 + h, u0, u0 + n)):
                if exact:
                    assert np.array_equal(got, ref), (n, h)
                else:  # 3 products and the offset: 4 roundings of 2^-24 each, twice
                    assert np.all(np.abs(got.astype(np.float64) - ref) <= 8 * 2.0**-24 * size), (n, h)


def test_peak_score_is_box_scores_bit_for_bit():
    # The search's window: projected levels against the felt, clipped, the
    # box score cut to the search's rows and columns; windows down to
    # smaller than the ring (OpenCV's border reflected more than once).
    from cuespin.track.background import box_score
    rng = np.random.default_rng(12)
    for i in range(600):
        h, w = (int(x) for x in rng.integers(3, 90, 2))
        k = int(rng.integers(1, 16)) | 1
        K = (2 * k) | 1
        P = (rng.normal(0, 8, (h, w)) + rng.uniform(0, 200)).astype(np.float32)
        if i % 3 == 0:  # grey video: whole levels
            P = np.round(P)
        felt = (P.mean() + rng.normal(0, 10) + rng.normal(0, 2, (h + 2, w + 2))).astype(np.float32)[1:-1, 1:-1]
        pol, cap = int(rng.choice([-1, 1])), np.float32(rng.uniform(5, 60))
        ref = box_score(np.clip(pol * (P - felt), -cap, cap), k, K)
        r0, c0 = int(rng.integers(0, h)), int(rng.integers(0, w))
        r1, c1 = int(rng.integers(r0 + 1, h + 1)), int(rng.integers(c0 + 1, w + 1))
        got = window.peak_score(P, felt, pol, cap, k, K, r0, r1, c0, c1)
        assert np.array_equal(got, ref[r0:r1, c0:c1]), (h, w, k, r0, r1, c0, c1)


def test_marks_beyond_is_the_numpy_form():
    # The markings rule's two fits: a shaded ball, with and without a dark
    # dot, blurred or not, some pixels not usable; the same pixels found.
    from cuespin.track.model import _model_rows, blur_nodes
    from cuespin.track.tracker import _marks_beyond, segment_distance
    rng = np.random.default_rng(13)
    found = 0
    for t in range(120):
        h = w = int(rng.integers(15, 45))
        r = h / 3.0
        c = np.array([w / 2 + rng.normal(), h / 2 + rng.normal()])
        b = rng.normal(0, 2, 2) * (t % 2)
        felt = (90 + rng.normal(0, 3, (h + 2, w + 2))).astype(np.float32)[1:-1, 1:-1]
        m0, JT = _model_rows(c, b, 0.0, felt, r, 0, 0, blur_nodes(np.hypot(*b)), np.zeros(3), False, None)
        ys, xs = np.mgrid[0:h, 0:w]
        disc = (xs - c[0]) ** 2 + (ys - c[1]) ** 2 < r * r
        patch = (felt + disc * (100 + 5 * (xs - c[0])) + rng.normal(0, 3, (h, w))).astype(np.float32)
        if t % 3 == 0:
            patch[(xs - c[0] - 2) ** 2 + (ys - c[1]) ** 2 < 4] -= 60
        inner = segment_distance(felt.shape, 0, 0, c, b) < r - 2
        use = np.ones(h * w, bool) if t % 4 else rng.random(h * w) > 0.1
        thresh = float(rng.uniform(5, 40))
        bad, n_bad, done = window.marks_beyond(patch, felt, m0, JT, use, inner.ravel(), thresh)
        ref = _marks_beyond(patch, felt, m0, JT, use, inner, thresh)
        assert done and n_bad == ref.sum() and np.array_equal(bad, ref), t
        found += n_bad >= 3
    assert found >= 20  # the dots are found: the rule's both branches compared
