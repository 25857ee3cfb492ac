"""How far the tracker's stated errors fall short on a ball whose look its model misses (pure).

The per-frame fit states its error from its own residuals, as if what it
does not model were independent noise in every pixel.  On a realistic ball
(shading the model only approximates, a highlight, markings that turn with
the spin, a lens blur) what it misses is the ball's look, the same from one
frame to the next but for the slow turn of the markings and the ball's
sub-pixel phase: its error in the centre is a bias that varies slowly along
the path, 1.5-3 times the stated error and correlated over many frames
(lag-1 0.7-0.95 at 480 fps).  No one frame shows it (the fit absorbs the
part of the misfit that looks like a shift), but the track does: third
differences of the centres, ``x[k+2s] - 3 x[k+s] + 3 x[k] - x[k-s]``, are
free of any quadratic motion (a sliding or rolling phase) at every spacing
``s``, and their variance grows with ``s`` until ``s`` exceeds the errors'
correlation time, where it reaches 20 times the errors' full variance.
:func:`look_misfit` fits that variogram with the stated (independent)
errors plus an AR(1) error of variance ``excess`` times the stated one, and
returns the factor ``1 + excess`` by which every frame's covariance must be
scaled to be honest, and the AR(1) error's lag-1 correlation.

What no track shows is the look's constant part (the same bias in every
frame: the shading's, towards or away from the light); it shifts the whole
path, which the recovery's ``x0`` absorbs (measured: 0.06-0.12 px on
shaded balls, ``benchmarks/track.py realistic``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cuespin.track.model import block_area

# Frame spacings of the third differences (frames).
SPACINGS = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32)
# A spacing's variance ratio counts once this many third differences of
# moving frames (both axes) enter it.
MIN_SAMPLES = 16
# A frame moves when its centre moves more than this (px per frame): only
# moving frames vary their misfit (a resting ball's is the same every frame).
MOVING_PX = 0.3
# The third differences at one spacing are pooled in blocks of consecutive
# frames, at least this many times the spacing and BLOCK_MIN long, and the
# variance is the median of the blocks' mean squares: a kink of the motion
# (the strike, the end of sliding, the stop: a jump in acceleration of up to
# mu_s g puts several stated errors into the differences that straddle it,
# 3 s of them, at spacings of 0.02-0.1 s) or a stray frame spoils one or
# two blocks, not the median.  Simulated tracks with such kinks and
# independent errors, 60-480 fps: a per-difference median clipped at 4
# sigma inflated 75-100% of them by 2.4-3.9 (kinks spoiling most of the
# differences at the longer spacings); blocked, 8-25% of them, by at most
# 3.3 (the short, low-noise ones), none at 0.05 px beyond 8%.
BLOCK_SPACINGS = 3
BLOCK_MIN = 4
# A spacing counts only with at least this many blocks: the strike spoils
# the first, the end of sliding one or two, and the median stays clean
# (with 4, simulated low-noise tracks were inflated 10-3000 times).  Blocks
# of 3 spacings rather than 4 reach longer spacings on short clips: on 33
# realistic 0.7-s tracks, err/se after the factor median 1.17 (FFV1) and
# 1.18 (MJPG) against 1.17 and 1.39 with blocks of 4.
MIN_BLOCKS = 5
# The excess is kept only beyond this many of its standard errors (one-sided
# 0.1%), so that a ball whose look the model holds keeps its errors as stated.
# Measured by simulation (benchmarks/calibrate_tests.py --which misfit;
# 2026-11-30, mixed_tracks seeds 1 and 2, 12,000 tracks with independent
# errors stated right, 60-480 fps, 0.01-0.3 px, 1,000 per cell): on tracks
# rolling from the strike 4 of 6,000 inflated (0.07%: nominal), on sliding
# ones 267 of 6,000 (4.5%; 1-10% per cell at 60-240 fps, 0-0.4% at 480),
# by factors 1.9/2.7/6.0 (p10/50/90), up to 12: the last still frame
# before the strike passed for moving, and the end of sliding spoiled two
# of the longest spacing's 5-6 blocks.  With the frames next to a still one
# left out (EDGE_FRAMES) and the end of sliding fitted out (KINK_GRID),
# 2026-11-30: sliding 2 of 1,000 (seed 4, 0.20%; z's 99.9th percentile
# 3.23) and 0 of 400 (seed 12, tests/test_track_misfit.py), rolling 0 of
# 400 (seed 11): 2 of 1,800, 0.11%, nominal.  (Without the kink fitted
# out, the edge frames alone: 2 of 400 sliding.)  Simulated excesses of
# 3-5 (the realistic looks') reach z 10-35.
EXCESS_Z = 3.09
# A correlation is considered only where the longest spacing's third
# differences reach this share of the error's full variance: beyond, the
# excess would be extrapolated from the variogram's rise alone (simulated
# AR(1) errors, rho 0.8, 100 frames: one factor in ten 7 times too large).
MIN_PLATEAU = 0.5
# A ratio that rises more than this many times from one spacing to the next
# (spacings at most 2 apart) is a kink of the motion spoiling most of the
# blocks, not the look: the strike, the end of sliding and the stop on a
# 100-frame low-noise track (1.5 m, 15 deg, k1 +0.25: ratios 0.86, 0.76,
# 0.90, 0.64, then 80 at spacing 6, which made the stated errors 10 times
# the real ones); the spacings stop there.  Realistic looks' misfits rose at
# most 3.6 times in one step (sample_scenes(1, 5, realistic, FFV1)[0]: 0.36,
# 1.78, 6.47, 9.05 at spacings 1-4).
MAX_RISE = 10.0
# The AR(1) error's lag-1 correlation is searched on this grid.
RHO_GRID = np.r_[0.0, np.linspace(0.05, 0.98, 32)]
# The end of sliding (a jump in acceleration from mu_s g to the rolling
# (5/7) mu_r g) is taken out of the centres before their third differences:
# one kink fitted to the moving frames (a quadratic in time with a term
# ``(t - tau)_+^2`` added, per axis, ``tau`` shared), its time searched on
# this many points over the moving frames and refined once on as many
# around the best.  The blocked median alone let it through at the longest
# spacing (2 of its 5-6 blocks straddle it): 267 of 6,000 simulated sliding
# tracks with independent errors inflated (4.45% against the nominal 0.1%).
KINK_GRID = 48
# Frames dropped at each end of a run of moving frames (see variance_ratios).
EDGE_FRAMES = 2

# An intra-frame lossy codec's (MJPG's) share of a chroma blocks' fit's
# error that its stated error leaves out.  Measured (codecerr12,
# docs/measurements.md): on the chroma's blocks the codec's error is most of
# the centre's (one shot's frames fitted from the true centre: RMSE
# 0.033-0.037 px on MJPG against 0.002-0.009 px on FFV1 at noise 0.5-8, and
# the same at every noise: the quantisation of the ball's own image), and
# the fit states it from its residuals (the jackknife's sandwich on a few
# clusters of blocks, track.model._jackknife_cov): within every track the
# frames stated smallest err most (mean squared err/se by the track's own
# terciles of stated error 1.05-3.3, 0.5-2.0, 0.3-1.0 on 14 shots), so the
# stated variance falls short on the whole.  The value: the median over
# the 17 luma-blind MJPG shots of `benchmarks/track.py realistic --n 20
# --seconds 0.8 --seed 0` of each shot's mean squared err/se over its
# moving frames before the look's factor, 1.47 (shots of even index 1.41,
# odd 1.49); err/se there median 1.21 -> 1.01, within 0.8-1.25 10 -> 14 of
# 17 (two uniform balls already stated too large, 0.60 and 0.85, go to
# 0.50 and 0.71).  Every blocks' fit's covariance on such a video is
# multiplied by it.  Out of sample (codecerr13, seed 1, 11 luma-blind
# shots): err/se median 1.22 -> 1.09, in band 6 -> 8 of 11; seed 1 alone
# would give 1.78 (bootstrap SE 0.22), not 1.47: the share differs between
# samples of colour pairs, and 1.45-1.78 give the same in-band count there.
# Review 9a: it is MJPG's whole excess on these fits, not the codec's alone
# (the same shots' FFV1 tracks, lit sphere aside, state ~1.2 too little in
# variance too: about 1.2 of it is the codec, 1.2 shared and uncorrected on
# FFV1), and 1.45 rounds the seed-0 median 1.47 down to the pooled seeds'
# side (1.52); the recovery still estimates a codec term of its own on top
# (recover.estimate's codec_excess), which takes up most of it there.
# One value for both image axes (mjpgerr7): per axis the seed-0 shots give
# 1.33 (u) and 1.54 (v), bootstrap SEs 0.13 and 0.15, no cross term (the
# whitened error's uv median -0.03); on seed 1 that pair leaves the
# in-band counts as the one value does (u 10, v 7 of 12).  OpenCV's MJPG
# writer (FFmpeg's swscale) averages the chroma's pairs along a row but
# filters its columns over 6 rows (-0.03, 0.10, 0.43, 0.43, 0.10, -0.03),
# a model of blocks does not; in controlled fits (seed 0 shots 2, 5, 7, 9,
# 48 frames each, the writer emulated with and without those taps) they
# raised v's error variance on 3 of 4 (geometric mean x1.14, u x0.96).
JPEG_CHROMA_VAR = 1.45


@dataclass(frozen=True)
class LookMisfit:
    """The track's verdict on its stated errors.

    Attributes
    ----------
    factor : float
        Every frame's covariance times this is its honest covariance (1:
        the stated errors hold).
    rho : float
        Lag-1 correlation (between consecutive frames) of the error the
        factor adds (0 when none is added).
    ratios : dict
        Per spacing (frames), the third differences' variance over what the
        stated errors give, and how many entered it (diagnostics).
    z : float
        The fitted excess over its standard error, the statistic the factor
        is kept on (beyond ``EXCESS_Z``; 0 when no spacing counts).
    """

    factor: float = 1.0
    rho: float = 0.0
    ratios: dict | None = None
    z: float = 0.0


def _shape(rho, s):
    """Variance of an AR(1) error's third difference at spacing ``s`` over 20 times its variance."""
    p = rho ** np.asarray(s, float)
    return (20.0 - 30.0 * p + 12.0 * p * p - 2.0 * p ** 3) / 20.0


def third_difference_weights(t, k, s) -> np.ndarray:
    """Weights of the third difference over frames ``k - s, k, k + s, k + 2s``
    taken at times ``t``: the third divided difference (zero on any quadratic
    in time) times ``6 h^3``, ``h`` the mean step, so that at a constant rate
    they are ``(-1, 3, -3, 1)`` exactly.  Shape (len(k), 4).

    At a variable frame rate (a phone's file) the plain ``(-1, 3, -3, 1)`` is
    not free of the motion: a ball moving at v leaves ``v`` times the
    intervals' own third difference in it (1 m/s, intervals jittered by 3% at
    120 fps: 0.06 px at 250 px/m, 2-10 times the tracker's error), which the
    variogram took for the look's misfit (H.264, 120 fps, jitter 0.03:
    factor 11.3 with lag-1 correlation 0.77 against 3.5 and 0.26 at a
    constant rate on the same shot).
    """
    t = np.asarray(t, float)
    pts = np.stack([t[k - s], t[k], t[k + s], t[k + 2 * s]], axis=1)      # (m, 4)
    diff = pts[:, :, None] - pts[:, None, :]
    diff[:, np.arange(4), np.arange(4)] = 1.0
    w = 1.0 / np.prod(diff, axis=2)
    h = (pts[:, 3] - pts[:, 0]) / 3.0
    return w * (6.0 * h**3)[:, None]


def remove_kink(x, w, t) -> np.ndarray:
    """``x`` with its fitted kink taken out (see ``KINK_GRID``).

    Parameters
    ----------
    x : ndarray, shape (n, 2)
        Centres of the frames to fit (px), all finite.
    w : ndarray, shape (n,)
        Their weights (1 / variance, px^-2).
    t : ndarray, shape (n,)
        Their times (any unit: frames or s).

    Returns
    -------
    ndarray, shape (n, 2)
        ``x`` less ``da (t - tau)_+^2``, ``da`` and ``tau`` the weighted
        least-squares kink over a quadratic in time (both axes share
        ``tau``); ``x`` unchanged when fewer than 8 frames.
    """
    x, w, t = np.asarray(x, float), np.asarray(w, float), np.asarray(t, float)
    if len(t) < 8:
        return x
    tc = (t - t.mean()) / max(np.ptp(t), 1e-300)          # conditioned: [-1/2, 1/2]
    base = np.stack([np.ones_like(tc), tc, tc * tc], axis=1)  # (n, 3)

    def fits(taus):
        """Weighted least squares for every kink time at once: the
        residual sum of squares (both axes) and the kink's coefficients."""
        K = np.clip(tc[None, :] - np.asarray(taus)[:, None], 0.0, None) ** 2       # (g, n)
        g = len(K)
        A = np.empty((g, 4, 4))
        A[:, :3, :3] = (base.T * w) @ base
        A[:, :3, 3] = A[:, 3, :3] = K @ (base * w[:, None])
        A[:, 3, 3] = K * K @ w
        b = np.empty((g, 4, 2))
        b[:, :3, :] = ((base.T * w) @ x)[None]
        b[:, 3, :] = K @ (w[:, None] * x)
        A[:, np.arange(4), np.arange(4)] += 1e-12 * np.abs(A[:, np.arange(4), np.arange(4)]).max()
        coef = np.linalg.solve(A, b)                                             # (g, 4, 2)
        rss = float(np.sum(w[:, None] * x * x)) - np.einsum("gkd,gkd->g", coef, b)
        return rss, coef[:, 3, :]

    lo, hi = tc.min(), tc.max()
    grid = np.linspace(lo, hi, KINK_GRID)
    best = grid[int(np.argmin(fits(grid)[0]))]
    step = (hi - lo) / (KINK_GRID - 1)
    fine = np.linspace(max(lo, best - step), min(hi, best + step), KINK_GRID)
    rss, da = fits(fine)
    k = int(np.argmin(rss))
    return x - np.clip(tc - fine[k], 0.0, None)[:, None] ** 2 * da[k][None, :]


def variance_ratios(uv, cov, ok, spacings=SPACINGS, t=None) -> dict:
    """Per spacing ``s``: the variance of the moving frames' third
    differences (a median over blocks of frames, so that the few blocks a
    kink of the motion spoils do not count; the spacings stop where a ratio
    rises more than ``MAX_RISE``-fold) over the
    variance the stated covariances give them (independent errors), and the
    number of differences kept (both axes).

    Parameters
    ----------
    uv : ndarray, shape (n, 2)
        Centres, one per frame in order: px, or table metres at a px scale
        (track.video: where the motion is a parabola or a line).
    cov : ndarray, shape (n, 2, 2)
        Their stated covariances (px^2).
    ok : ndarray of bool, shape (n,)
    t : ndarray, shape (n,), optional
        Frame times (s); None: a constant rate.  At a variable rate the
        differences are weighted by :func:`third_difference_weights`.
    """
    uv = np.asarray(uv, float)
    var = np.diagonal(np.asarray(cov, float), axis1=1, axis2=2)
    good = np.asarray(ok, bool) & np.all(np.isfinite(uv), axis=1) & np.all(var > 0, axis=1)
    x = np.where(good[:, None], uv, np.nan)
    var = np.where(good[:, None], var, np.nan)
    n = len(x)
    speed = np.full(n, np.nan)
    speed[1:-1] = np.hypot(*(x[2:] - x[:-2]).T) / 2.0
    with np.errstate(invalid="ignore"):
        moving = speed > MOVING_PX
        still = speed <= MOVING_PX  # a lost frame's neighbours (nan) are neither
    # Not the frames next to a still one: the last still frame before the
    # strike passes for moving (its next frame moved), and the frame whose
    # exposure spans the strike is no quadratic (the strike is a kink of the
    # velocity, not of the acceleration); the same at the stop.  Only still
    # frames, not lost ones: eroding around each lost frame cost ~5 moving
    # frames apiece (review: at 60 fps with 10% lost, a factor-4 misfit was
    # found 65% of the time against 77.5%).
    for _ in range(EDGE_FRAMES):
        still = still | np.r_[False, still[:-1]] | np.r_[still[1:], False]
    moving &= ~still
    fit = moving & good
    if fit.sum() >= 8:  # the end of sliding out of the moving frames (KINK_GRID)
        tk = np.arange(n, dtype=float) if t is None else np.asarray(t, float)
        x = x.copy()
        x[fit] = remove_kink(x[fit], 2.0 / (var[fit, 0] + var[fit, 1]), tk[fit])
    out = {}
    for s in spacings:
        k = np.arange(s, n - 2 * s)
        if len(k) < MIN_SAMPLES // 2:
            break
        if t is None:
            d3 = x[k + 2 * s] - 3 * x[k + s] + 3 * x[k] - x[k - s]
            v3 = var[k + 2 * s] + 9 * var[k + s] + 9 * var[k] + var[k - s]
        else:
            c = third_difference_weights(t, k, s)[:, :, None]          # (m, 4, 1)
            idx = np.stack([k - s, k, k + s, k + 2 * s], axis=1)
            d3 = np.sum(c * x[idx], axis=1)
            v3 = np.sum(c * c * var[idx], axis=1)
        use = moving[k - s] & moving[k] & moving[k + s] & moving[k + 2 * s]
        with np.errstate(invalid="ignore"):
            z2 = (d3 * d3 / v3).sum(axis=1)          # both axes: 2 degrees of freedom
        use &= np.isfinite(z2)
        L = max(BLOCK_SPACINGS * s, BLOCK_MIN)
        block = (k - s) // L
        ms, counts = [], []
        for b in np.unique(block[use]):
            zb = z2[use & (block == b)]
            if len(zb) >= L // 2:
                ms.append(zb.mean() / 2.0)
                counts.append(2 * len(zb))
        if len(ms) < MIN_BLOCKS or sum(counts) < MIN_SAMPLES:
            break
        V, m = float(np.median(ms)), int(sum(counts))
        if out and V > MAX_RISE * max(out[max(out)][0], 1.0):
            break
        out[s] = (V, m)
    return out


def look_misfit(uv, cov, ok, t=None) -> LookMisfit:
    """Scale factor for the stated covariances of a track, and the lag-1
    correlation of the error it adds (see the module's docstring).

    The variance ratios ``V_s`` (:func:`variance_ratios`) are fitted by
    ``1 + excess * shape(rho, s)``, ``shape`` the AR(1) error's third
    difference variance (1 at long spacings), weighted by each ratio's
    sampling variance (``2 / n_s``; overlapping differences at one spacing
    are counted as independent, see below); ``rho`` on a
    grid, ``excess`` in closed form.  The factor is ``1 + excess`` when the
    excess passes ``EXCESS_Z`` of its standard error, else 1.  ``t``: the
    frame times (s) at a variable rate (:func:`variance_ratios`).
    """
    ratios = variance_ratios(uv, cov, ok, t=t)
    if not ratios:
        return LookMisfit(ratios=ratios)
    s = np.array(list(ratios), float)
    V = np.array([ratios[k][0] for k in ratios])
    n = np.array([ratios[k][1] for k in ratios], float)
    # Each ratio's sampling variance, 2 / n (a mean square of n normal
    # deviates) at the independent-error model's value 1 rather than at the
    # noisy V itself, which would favour the spacings that came out small
    # by chance.
    w = n / 2.0
    best = None
    # Two spacings or fewer cannot tell a correlated error's rho: independent.
    for rho in (RHO_GRID if len(s) > 2 else (0.0,)):
        f = _shape(rho, s) if rho > 0 else np.ones_like(s)
        if f[-1] < MIN_PLATEAU:
            continue  # the spacings never reach this error's plateau: no extrapolation
        den = float(np.sum(w * f * f))
        c = float(np.sum(w * f * (V - 1.0))) / den
        sse = float(np.sum(w * (V - 1.0 - c * f) ** 2))
        if best is None or sse < best[0]:
            best = (sse, c, rho, 1.0 / np.sqrt(den))
    _, c, rho, se_c = best
    # The differences overlap (each frame enters four of them, and the
    # errors are correlated): the effective count is smaller; the largest
    # spacing's terms are the least dependent, so its standard error,
    # scaled, is the one to beat.
    se_c *= np.sqrt(float(s.max()))
    z = c / se_c
    if not z > EXCESS_Z:
        return LookMisfit(ratios=ratios, z=z)
    return LookMisfit(factor=1.0 + c, rho=float(rho), ratios=ratios, z=z)


__all__ = ["JPEG_CHROMA_VAR", "LookMisfit", "codec_variance", "look_misfit", "remove_kink",
           "third_difference_weights", "variance_ratios"]


def codec_variance(lossless: bool, inter_frame: bool, block) -> float:
    """What a frame's stated covariance is multiplied by for the codec's
    error it leaves out: ``JPEG_CHROMA_VAR`` for fits on the chroma's blocks
    (``block`` more than a pixel, track.model.fit_disc) of a lossy codec that codes every
    frame on its own (MJPG); 1 otherwise.  A lossless 4:2:0 stream's blocks
    carry no quantisation; an inter-frame codec's error is modelled in the
    recovery (recover.mle.INTER_CODEC_ACF, measured with the tracker's
    stated variance taken off); pixels' fits (grey, or a projection seeing
    luma) are left as stated.
    """
    return JPEG_CHROMA_VAR if (not lossless and not inter_frame and block_area(block) > 1) else 1.0


def error_ar1(factor: float, rho: float) -> float:
    """The lag-1 correlation of the AR(1) error model the recovery fits under
    (recover.estimate.estimate's ``ar1_floor``) for covariances stated as
    independent, scaled by ``factor`` (:func:`look_misfit`), the share
    ``(factor - 1) / factor`` that scaling adds AR(1) with lag-1 correlation
    ``rho``: the one of the same long-run variance, ``(1 + r) / (1 - r) =
    (1 + (factor - 1) (1 + rho) / (1 - rho)) / factor``, what a correlated
    error costs a velocity.  0 when nothing correlated is added.

    Not the total error's own lag-1 correlation ``rho (factor - 1) / factor``:
    fitted under that, v0 and w0 were covered 81% and 75% of the time
    (tests/test_look_rho.py: rho 0.9, factor 4; their errors 1.6 times the
    stated in median); under this one 100% and 97% (0.65-0.85 times: on the
    safe side); with the residuals' correlation alone, 61% and 58%.
    """
    factor, rho = float(factor), float(rho)
    if factor <= 1.0 or rho <= 0.0:
        return 0.0
    g = (1.0 + (factor - 1.0) * (1.0 + rho) / (1.0 - rho)) / factor
    return (g - 1.0) / (g + 1.0)
