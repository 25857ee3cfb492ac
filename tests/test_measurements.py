"""recover/measurements.py and the error model around it: degrees of freedom,
masks, rests as one measurement, per-position covariance, autocorrelated
errors (HAC), and the paper's answers' status and errors."""

import numpy as np
import pytest

from cuespin.data_gen.sampler import sample_shot
from cuespin.physics import phases
from cuespin.recover.api import recover_track
from cuespin.recover.measurements import build_measurements, stated_frames
from cuespin.recover.mle import model_track
from cuespin.recover.simulate import simulate_track

SIGMA = 1e-4


def rolling_track(seed=3, fps=120.0, preset="case3"):
    shot, p = sample_shot(seed, preset)
    ph = phases(shot, p)
    return shot, p, simulate_track(shot, p, fps, SIGMA, seed, t_end=min(ph.t2 + 0.5, shot.t0 + 4.0))


def test_rests_are_one_measurement_each_and_strike_frames_masked():
    t = np.arange(100) / 100.0
    xy = np.zeros((100, 2))
    m = build_measurements(t, xy, np.full(100, SIGMA), t0=0.2, t_rest=0.8, exposure_s=0.005,
                           frame_dt=0.01, shared_rest=True)
    assert not m.used[20] and m.used[18] and m.used[22]       # the strike's frame is masked
    before = np.unique(m.group[:19])
    after = np.unique(m.group[82:])
    assert len(before) == 1 and len(after) == 1               # each rest one measurement
    in_rest = np.isin(m.group, np.r_[before, after])
    assert m.n == int(np.sum(m.used & ~in_rest)) + 2 and m.dof(7) == 2 * m.n - 7
    # Lossless: a rest of 10 frames or more is one measurement too (its
    # covariance from its scatter); here the 20 frames before the strike.
    lossless = build_measurements(t, xy, np.full(100, SIGMA), t0=0.2, exposure_s=0.005, frame_dt=0.01)
    assert lossless.n == 99 - 20 + 1 and lossless.dof(7) == 2 * 80 - 7
    short = build_measurements(t[15:], xy[15:], np.full(85, SIGMA), t0=0.2, exposure_s=0.005, frame_dt=0.01)
    assert short.n == 84                                      # 4 still frames: each its own


def _rest_variance(xy_rest):
    """Per-axis variance of a lossless rest's mean (its measurement's), in SIGMA^2."""
    n = len(xy_rest)
    t = np.arange(n + 30) / 100.0
    xy = np.vstack([xy_rest, np.c_[np.linspace(0.01, 0.3, 30), np.zeros(30)]])
    m = build_measurements(t, xy, np.full(len(t), SIGMA), t0=(n + 0.5) / 100.0, exposure_s=0.005, frame_dt=0.01)
    c = np.linalg.inv(m.W[0] @ m.W[0].T) / SIGMA**2
    return np.diag(c)


def test_lossless_rest_shares_what_its_scatter_does_not_show():
    # Identical frames (a still image at no noise: the same 8-bit rounding
    # in each) share their whole error: the mean is no better than a frame.
    assert _rest_variance(np.full((40, 2), 1e-5)) == pytest.approx([1.0, 1.0])
    # Independent frames at the stated error: the mean's error is 1/n of a
    # frame's, more only where the scatter falls below independent frames'
    # REST_SHARED_LEVEL point by chance (f = 1 - l then).  Over 400 seeds,
    # n = 40: 1.30 / n on average (sd 1.98 / n; more than 1 / n on 2.25% of
    # them; 3.67 / n with f = (1 - l)+ for every rest, before); the mean
    # over 40 seeds is held within 3 of its standard errors.
    v = np.array([_rest_variance(SIGMA * np.random.default_rng(seed).standard_normal((40, 2)))[0]
                  for seed in range(40)]) * 40
    assert v.min() >= 1 - 1e-9 and 1.30 - 3 * 0.31 < v.mean() < 1.30 + 3 * 0.31, v.mean()
    # Frames showing a quarter of the stated error: 15/16 of it is shared.
    xy = 0.25 * SIGMA * np.random.default_rng(9).standard_normal((400, 2))
    v = _rest_variance(xy)
    assert np.all((v > 0.85) & (v < 0.95)), v


def _share_claimed(n, stated_over_real, scale_dof, seeds=2000):
    """How often an independent rest of ``n`` frames, the tracker stating
    ``stated_over_real`` times their real error, is given a shared share:
    judged against the moving frames' scale measured on ``scale_dof``
    degrees of freedom (the first fit's chi2/dof), or against 1 (None)."""
    from cuespin.recover.measurements import group_covariance, group_scatter

    rng = np.random.default_rng(3)
    C = np.broadcast_to(np.eye(2), (n, 2, 2)).copy()
    g = np.zeros(n, int)
    hits = 0
    for _ in range(seeds):
        xy = rng.standard_normal((n, 2)) / stated_over_real
        scale = (1.0, np.inf) if scale_dof is None else (
            rng.chisquare(scale_dof) / scale_dof / stated_over_real**2, scale_dof)
        hits += group_covariance(C, g, 1, group_scatter(xy, g, True), 0.0, *scale)[0, 0, 0] > 1.0 / n + 1e-12
    return hits / seeds


def test_lossless_rest_shares_at_its_level_with_the_trackers_overstated_errors():
    # Review 6: the tracker states 1.18 times its real error on FFV1 at
    # noise < 0.5 (moving frames' chi2/dof 0.72).  Judged against C, an
    # independent rest of 50 frames passed for shared 65% of the time;
    # against the moving frames' measured scale (150 dof: 75+ moving frames)
    # at REST_SHARED_LEVEL, held within 3 binomial standard errors (2000
    # rests: 0.35%).  Exact stated errors: the same level either way.
    from cuespin.recover.measurements import REST_SHARED_LEVEL

    se = 3 * np.sqrt(REST_SHARED_LEVEL * (1 - REST_SHARED_LEVEL) / 2000)
    assert _share_claimed(50, 1.18, None) > 0.5
    for n, over in ((10, 1.18), (50, 1.18), (100, 1.18), (50, 1.0)):
        rate = _share_claimed(n, over, 150)
        assert abs(rate - REST_SHARED_LEVEL) < se, (n, over, rate)
    assert abs(_share_claimed(50, 1.0, None) - REST_SHARED_LEVEL) < se


def test_moving_scale_is_the_single_frames_chi2_per_dof():
    # A track with a resting start: the scale is the moving frames' whitened
    # residuals' mean square, the rest's mean left out.
    from cuespin.recover.measurements import moving_scale

    t = np.arange(100) / 100.0
    m = build_measurements(t, np.zeros((100, 2)), np.full(100, SIGMA), t0=0.2, exposure_s=0.005, frame_dt=0.01)
    r = np.random.default_rng(1).standard_normal((m.n, 2))
    r[~m.single] = 50.0
    s, dof = moving_scale(m, r, 7)
    assert dof == 2 * m.single.sum() - 7
    assert s == pytest.approx(np.sum(r[m.single] ** 2) / dof)
    assert moving_scale(m, r[:3], 7) == (1.0, np.inf)


def test_chi2_per_dof_near_one_with_shared_rest_errors():
    # A lossy codec's rests: every still frame carries the same error (plus
    # a little of its own); fitted as lossy, chi2/dof must be ~1 (it was
    # 0.51-0.73 when every frame counted 2 dof).  Measured over these seeds:
    # median 1.00; held to 0.9-1.1.
    chis = []
    for seed in range(6):
        shot, p = sample_shot(40 + seed, "random")
        ph = phases(shot, p)
        rng = np.random.default_rng(seed)
        t = np.arange(0.0, min(ph.t2 + 0.5, 4.0), 1 / 120)
        xy = model_track(shot, p, t) + SIGMA * rng.standard_normal((len(t), 2))
        still0 = t < shot.t0
        xy[still0] = model_track(shot, p, t[still0]) + SIGMA * rng.standard_normal(2) \
            + 0.05 * SIGMA * rng.standard_normal((still0.sum(), 2))
        still2 = t > ph.t2
        if still2.any():
            xy[still2] = model_track(shot, p, t[still2]) + SIGMA * rng.standard_normal(2) \
                + 0.05 * SIGMA * rng.standard_normal((still2.sum(), 2))
        m = recover_track(t, xy, np.ones(len(t), bool), np.full(len(t), SIGMA), p,
                          lossless=False)["methods"]["mle"]
        assert m["status"] in ("ok", "degenerate"), m["reason"]
        chis.append(m["chi2_per_dof"])
    assert 0.9 <= np.median(chis) <= 1.1, chis


def test_per_position_covariance_is_what_the_fit_weights_by():
    # Errors whose size varies along the path (a tilted camera: 0.87-1.34x
    # across the table) and are anisotropic: given as 2x2 covariances, the
    # fit's chi2/dof is ~1 (measured 0.98-1.03 over seeds 0-3).
    shot, p = sample_shot(5, "random")
    ph = phases(shot, p)
    t = np.arange(0.0, min(ph.t2 + 0.3, 4.0), 1 / 240)
    clean = model_track(shot, p, t)
    scale = np.interp(clean[:, 0], [0.0, 2.54], [0.87, 1.34]) * SIGMA
    cov = np.zeros((len(t), 2, 2))
    cov[:, 0, 0], cov[:, 1, 1], cov[:, 0, 1] = scale**2, (0.5 * scale) ** 2, 0.3 * scale**2
    cov[:, 1, 0] = cov[:, 0, 1]
    rng = np.random.default_rng(0)
    xy = clean + np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal((len(t), 2)))
    m = recover_track(t, xy, np.ones(len(t), bool), cov, p)["methods"]["mle"]
    assert m["status"] == "ok" and m["chi2_per_dof"] == pytest.approx(1.0, abs=0.08)
    z = (np.array(m["v0"]) - shot.v0) / np.array(m["stderr"]["v0"])
    assert np.abs(z).max() < 4


def test_autocorrelated_errors_widen_the_errors():
    # AR(1) errors with lag-1 autocorrelation 0.67 (MJPG at low noise):
    # the residuals show it, the fit models the errors as AR(1) with that
    # correlation (prewhitened residuals left uncorrelated), and the standard
    # errors grow (by up to sqrt((1 + rho) / (1 - rho)) = 2.3 for a slowly
    # varying parameter).
    shot, p = sample_shot(7, "random")
    ph = phases(shot, p)
    t = np.arange(0.0, min(ph.t2 + 0.3, 4.0), 1 / 240)
    rng = np.random.default_rng(1)
    e = np.zeros((len(t), 2))
    rho = 0.67
    w = rng.standard_normal((len(t), 2)) * SIGMA * np.sqrt(1 - rho**2)
    e[0] = SIGMA * rng.standard_normal(2)
    for k in range(1, len(t)):
        e[k] = rho * e[k - 1] + w[k]
    xy = model_track(shot, p, t) + e
    ok = np.ones(len(t), bool)
    m = recover_track(t, xy, ok, np.full(len(t), SIGMA), p)["methods"]["mle"]
    assert m["ar1"] == pytest.approx(rho, abs=0.1) and abs(m["rho1"]) < 0.1
    iid = recover_track(t, model_track(shot, p, t) + SIGMA * rng.standard_normal((len(t), 2)), ok,
                        np.full(len(t), SIGMA), p)["methods"]["mle"]
    assert not iid["hac"] and iid["ar1"] == 0.0
    assert np.mean(np.array(m["stderr"]["v0"]) / np.array(iid["stderr"]["v0"])) > 1.25


def test_bound_under_the_fits_ar1_errors():
    # The Cramer-Rao bound of the same measurements under the same error
    # model: with the AR(1) errors the fit found, its v0 errors match the
    # fit's own (the same information, at the truth rather than the
    # estimate; measured within 3e-5), while the bound with every frame
    # independent is about half as wide (measured 2.0-2.15 times narrower).
    from cuespin.recover.mle import crb_covariance

    shot, p = sample_shot(7, "random")
    ph = phases(shot, p)
    t = np.arange(0.0, min(ph.t2 + 0.3, 4.0), 1 / 240)
    rng = np.random.default_rng(1)
    rho = 0.67
    e = np.zeros((len(t), 2))
    e[0] = SIGMA * rng.standard_normal(2)
    for k in range(1, len(t)):
        e[k] = rho * e[k - 1] + SIGMA * np.sqrt(1 - rho**2) * rng.standard_normal(2)
    out, est = recover_track(t, model_track(shot, p, t) + e, np.ones(len(t), bool), np.full(len(t), SIGMA), p,
                             return_estimate=True)
    m = est.mle
    assert m.status == "ok" and m.model == "full" and m.ar1 > 0.5
    se_v0 = np.sqrt(np.diag(crb_covariance(shot, p, est.meas, ar1=m.ar1))[3:5])
    iid_v0 = np.sqrt(np.diag(crb_covariance(shot, p, est.meas))[3:5])
    assert np.allclose(se_v0 / np.asarray(m.stderr["v0"]), 1.0, atol=0.05), se_v0 / np.asarray(m.stderr["v0"])
    assert np.all(se_v0 / iid_v0 > 1.6), se_v0 / iid_v0


def test_bound_refuses_ar1_and_a_codecs_correlation_together():
    # AR(1) errors and an inter-frame codec's correlation are the fit's two
    # alternative error models (recover.estimate fits AR(1) only without a
    # codec); given both, the bound would whiten the errors twice and come
    # out too narrow (review SHOULD-FIX 10).  Either alone still answers.
    from cuespin.recover.mle import INTER_CODEC_ACF, crb_covariance

    shot, p = sample_shot(7, "random")
    t = np.arange(0.0, 1.0, 1 / 120)
    meas = build_measurements(t, model_track(shot, p, t), np.full(len(t), SIGMA), t0=shot.t0, frame_dt=1 / 120)
    with pytest.raises(ValueError):
        crb_covariance(shot, p, meas, ar1=0.5, acf=INTER_CODEC_ACF)
    for kw in ({"ar1": 0.5}, {"acf": INTER_CODEC_ACF}, {"ar1": 0.0, "acf": INTER_CODEC_ACF}):
        assert np.all(np.isfinite(np.diag(crb_covariance(shot, p, meas, **kw))))


def test_shared_errors_on_a_lossless_codec_measure_no_codec_share():
    # A shaded look on a lossless codec: the tracker states errors the look
    # factor widened (here twice the real ones) and shared by a rest's
    # frames (independent False), but there is no codec error to measure.
    # Passed as a lossy codec, the codec share came out negative (-3/4 of
    # the stated variance) and shrank v0's errors to 0.55 of what the
    # stated errors give; kept apart (lossless, independent False) they stay
    # as stated (measured 1.11: the rest one measurement, before its
    # lossless baseline judged the rest's scatter against the moving frames'
    # scale: at twice the real errors it called the independent rest shared
    # (l = 0.25); now l / s near 1, the rest C / n: measured 1.43, 1.40).
    shot, p = sample_shot(7, "random")
    ph = phases(shot, p)
    t = np.arange(0.0, min(ph.t2 + 0.3, 4.0), 1 / 240)
    xy = model_track(shot, p, t) + SIGMA * np.random.default_rng(3).standard_normal((len(t), 2))
    ok, stated = np.ones(len(t), bool), np.full(len(t), 2 * SIGMA)

    def se_v0(**kw):
        m = recover_track(t, xy, ok, stated, p, **kw)["methods"]["mle"]
        assert m["status"] == "ok"
        return np.array(m["stderr"]["v0"]), m["codec_noise_m"]

    indep, _ = se_v0(lossless=True)
    lossy, c_lossy = se_v0(lossless=False)
    shared, c_shared = se_v0(lossless=True, independent=False)
    assert c_lossy < 0 and np.all(lossy / indep < 0.7)
    assert c_shared == 0.0 and np.all(shared / indep >= 1.0) and np.all(shared / indep < 1.6)


def test_paper_degenerate_when_the_strike_is_not_in_view():
    # The track starts mid-slide: the paper's method has no x0 (it said
    # "ok" with a wrong v0 before issue 11); nor does the fit extrapolate the
    # strike (recover.mle's strike_seen, gross13: any later point of a slide
    # starts the same motion, so t0 trades off against x0 and v0).
    shot, p = sample_shot(12, "masse")
    ph = phases(shot, p)
    tr = simulate_track(shot, p, 240.0, SIGMA, 2, t_start=shot.t0 + 0.3 * (ph.t1 - shot.t0),
                        t_end=min(ph.t2 + 0.3, ph.t1 + 1.0))
    out = recover_track(tr.t, tr.xy, np.ones(len(tr.t), bool), np.full(len(tr.t), SIGMA), p)
    paper = out["methods"]["paper"]
    assert paper["status"] == "degenerate" and "strike is not in view" in paper["reason"]
    assert out["best"] == ("mle" if out["methods"]["mle"]["status"] == "ok" else None)
    assert out["methods"]["mle"]["status"] == "degenerate"


def test_best_is_null_when_no_method_answers():
    t = np.arange(200) / 120.0
    xy = np.full((200, 2), 0.5) + SIGMA * np.random.default_rng(0).standard_normal((200, 2))
    out = recover_track(t, xy, np.ones(200, bool), np.full(200, SIGMA), sample_shot(1)[1])
    assert {m["status"] for m in out["methods"].values()} == {"failed"}
    assert out["best"] is None


def test_paper_states_errors_that_cover():
    # The paper's stated errors on simulated curved shots: measured RMS
    # z 1.2 over these seeds (stated errors optimistic by ~20%); held to
    # below 2.5 (issue 11 target: coverage 90-97%, see README).
    zs = []
    for seed in range(8):
        shot, p = sample_shot(60 + seed, "masse")
        ph = phases(shot, p)
        tr = simulate_track(shot, p, 240.0, SIGMA, seed, t_end=min(ph.t2 + 0.3, ph.t1 + 1.0))
        out = recover_track(tr.t, tr.xy, np.ones(len(tr.t), bool), np.full(len(tr.t), SIGMA), p)
        pp = out["methods"]["paper"]
        if pp["status"] == "ok":
            zs.append((np.r_[pp["v0"], pp["w0"]] - np.r_[shot.v0, shot.w0])
                      / np.r_[pp["stderr"]["v0"], pp["stderr"]["w0"]])
    assert len(zs) >= 5
    assert np.sqrt(np.mean(np.square(zs))) < 2.5, np.sqrt(np.mean(np.square(zs)))


def test_linear_covariance_is_the_fits_measurement_model():
    # The paper's inputs' errors come from the same measurement model as the
    # fit's (recover.measurements.linear_covariance): a rest's mean gets its
    # measurement's covariance exactly, on a lossy codec's rest (a shared
    # share) and on a lossless one; a single frame its own covariance; two
    # frames of one rest f C between them.
    from cuespin.recover.measurements import group_shares, group_scatter, linear_covariance
    rng = np.random.default_rng(4)
    t = np.arange(60) / 120.0
    xy = np.c_[np.where(t < 0.2, 0.0, 0.3 * (t - 0.2)), np.zeros(60)] + 1e-4 * rng.standard_normal((60, 2))
    cov = np.full(60, 1e-4)
    for shared in (True, False):
        meas = build_measurements(t, xy, cov, t0=0.2, frame_dt=1 / 120.0, shared_rest=shared)
        rest = np.flatnonzero(meas.group == 0)
        assert len(rest) >= 10
        W = np.zeros((3, 60))
        W[0, rest] = 1.0 / len(rest)
        W[1, 40] = 1.0
        W[2, rest[0]] = W[2, rest[1]] = 0.5
        C = linear_covariance(meas, W)
        mean_cov = np.linalg.inv(meas.W[0].T @ meas.W[0])
        assert np.allclose(C[0:2, 0:2], mean_cov, rtol=1e-9)
        assert np.allclose(C[2:4, 2:4], meas.cov[40], rtol=1e-12)
        used = meas.used
        c, f = group_shares(meas.cov[used], meas.group[used], meas.n,
                            group_scatter(meas.xy, meas.group, meas.rest_scatter), meas.rest_min_share)
        assert (f[0] >= 0.06) == shared
        assert np.allclose(C[4:6, 4:6], 0.5 * (meas.cov[rest[0]] + meas.cov[rest[1]]) / 2 + 0.5 * f[0] * c[0])


def _a_slides_single_frames(seed):
    """A 120-fps track (rest, then a slide from t0 0.2 s), its measurements,
    the slide's single frames and three weight rows on them: an average, one
    frame, and weights of both signs."""
    rng = np.random.default_rng(seed)
    t = np.arange(60) / 120.0
    xy = np.c_[np.where(t < 0.2, 0.0, 0.3 * (t - 0.2)), np.zeros(60)] + 1e-4 * rng.standard_normal((60, 2))
    cov = rng.uniform(0.5e-4, 2e-4, 60)
    meas = build_measurements(t, xy, cov, t0=0.2, frame_dt=1 / 120.0)
    one = np.flatnonzero(meas.used)
    one = one[meas.single[meas.group[one]]]
    assert len(one) >= 20
    W = np.zeros((3, 60))
    W[0, one] = 1.0 / len(one)
    W[1, one[5]] = 1.0
    W[2, one] = np.linspace(-1.0, 1.0, len(one)) / len(one)
    return meas, one, W


def _brute_covariance(W, L, R):
    """The weight rows' (x, y) covariance by brute force: R_ij L_i L_j^T
    summed over frame pairs (L each frame's Cholesky factor)."""
    Y = np.einsum("ai,ijk->aijk", W, L)
    return np.einsum("aipl,ij,bjql->apbq", Y, R, Y).reshape(2 * len(W), 2 * len(W))


def test_linear_covariance_carries_the_fits_ar1_errors_and_scale():
    # The paper's inputs are measured by the frames the MLE fits; when the
    # fit models their errors as AR(1) (recover.mle.ar1_prewhiten) and
    # scales them by chi2/dof, so must the inputs' covariance (seed 21's
    # realistic shots: rho up to 0.92).  Checked against the full frame
    # covariance, rho^|i - j| L_i L_j^T between the moving frames, built
    # by brute force: an average, a single frame, and weights of both signs.
    from cuespin.recover.measurements import linear_covariance
    meas, one, W = _a_slides_single_frames(5)
    rho, scale = 0.6, 2.5
    base = linear_covariance(meas, W)
    L = np.linalg.cholesky(meas.cov[one])
    k = np.rint((meas.t[one] - meas.t[one[0]]) * 120.0).astype(int)
    R = rho ** np.abs(k[:, None] - k[None, :]) - np.eye(len(one))
    extra = _brute_covariance(W[:, one], L, R)
    got = linear_covariance(meas, W, rho, scale)
    assert np.allclose(got, scale * (base + extra), rtol=1e-9, atol=1e-20)
    # A mean of m frames under AR(1) is (1 + rho) / (1 - rho) times less
    # precise than independent frames, to within end effects.
    assert got[0, 0] / (scale * base[0, 0]) > 0.8 * (1 + rho) / (1 - rho)

    # Per-axis weights (scalar estimates) give the same numbers: x and y as
    # two scalars each.
    G = np.zeros((6, 60, 2))
    G[0::2, :, 0] = G[1::2, :, 1] = W
    assert np.allclose(linear_covariance(meas, G, rho, scale), got, rtol=1e-12, atol=1e-22)


def test_linear_covariance_carries_an_inter_frame_codecs_correlation():
    # On H.264 the fit states its errors with each frame's whole error
    # shared with its neighbours in time (recover.mle.shared_sandwich:
    # rho(dt) of time_correlation between the moving frames' whitened
    # errors); the paper's inputs, measured by the same frames, must carry
    # it too (paper11: without it the paper's 95% intervals covered 75.0%
    # on realistic H.264 seed 34).  Checked against the full frame
    # covariance, rho(dt_ij) L_i L_j^T between the moving frames, by brute force.
    from cuespin.recover.measurements import linear_covariance
    from cuespin.recover.mle import INTER_CODEC_ACF, time_correlation
    meas, one, W = _a_slides_single_frames(6)
    base = linear_covariance(meas, W)
    L = np.linalg.cholesky(meas.cov[one])
    R = time_correlation(meas.t[one], INTER_CODEC_ACF) - np.eye(len(one))
    extra = _brute_covariance(W[:, one], L, R)
    got = linear_covariance(meas, W, 0.0, 1.5, acf=INTER_CODEC_ACF)
    assert np.allclose(got, 1.5 * (base + extra), rtol=1e-9, atol=1e-20)
    assert got[0, 0] > 1.5 * 3 * base[0, 0]  # a mean of tens of frames: several times less precise


def test_the_codecs_correlation_reaches_frames_the_fit_left_out():
    # The paper's segmentation weights frames the fit leaves out (the
    # strike's window, the cue's touched run); the codec shares their
    # errors with their neighbours as with any other frame's.  Before, only
    # the fit's frames were correlated: x0 from a slide's first 30 frames at
    # 120 fps, 12 of them in a 100-ms window left out, had its sd 1.80
    # times too small (the review's /tmp/revs/lc.py).  Weights on the
    # window's frames, on the fit's, and on both, checked against the full
    # frame covariance, rho(dt_ij) L_i L_j^T between every frame outside
    # the rest, by brute force.
    from cuespin.recover.measurements import linear_covariance
    from cuespin.recover.mle import INTER_CODEC_ACF, time_correlation
    rng = np.random.default_rng(7)
    n = 90
    t = np.arange(n) / 120.0
    xy = np.c_[np.where(t < 0.2, 0.0, 0.3 * (t - 0.2)), np.zeros(n)] + 1e-4 * rng.standard_normal((n, 2))
    cov = rng.uniform(0.5e-4, 2e-4, n)
    meas = build_measurements(t, xy, cov, t0=0.2, frame_dt=1 / 120.0, clear_s=0.1)
    moving = np.flatnonzero(t > 0.2)
    left_out = moving[~meas.used[moving]]
    assert len(left_out) >= 10  # the 100-ms window after the strike
    rest = meas.used & ~meas.single[np.maximum(meas.group, 0)]
    out = np.flatnonzero(~rest)  # every frame outside the rest, used or not
    W = np.zeros((3, n))
    W[0, left_out] = 1.0 / len(left_out)
    slide = moving[:30]  # x0 extrapolated from the slide's first 30 frames, as a segmentation takes it
    W[1, slide] = np.linalg.pinv(np.c_[np.ones(30), t[slide] - 0.2])[0]
    W[2, moving] = np.linspace(-1.0, 1.0, len(moving)) / len(moving)
    got = linear_covariance(meas, W, 0.0, 1.5, acf=INTER_CODEC_ACF)
    L = np.linalg.cholesky(meas.cov[out])
    R = time_correlation(meas.t[out], INTER_CODEC_ACF)
    brute = _brute_covariance(W[:, out], L, R)
    assert np.allclose(got, 1.5 * brute, rtol=1e-9, atol=1e-20)
    # The fit's frames alone miss most of it: a window's mean is far less
    # precise than its frames taken as independent.
    assert got[0, 0] > 1.5 * 3 * linear_covariance(meas, W)[0, 0]


def test_parabola_weights_are_the_converged_fits_linearisation():
    # recover.paper.parabola_weights: the orthogonal fit's (log a, theta,
    # vertex) move with its points as G . dp; checked against refits of
    # points moved by a small dp (fit.conics.fit_parabola to convergence).
    from cuespin.fit.conics import fit_parabola
    from cuespin.physics.parabola import Parabola
    from cuespin.recover.paper import parabola_weights
    rng = np.random.default_rng(3)
    par = Parabola(a=4.0, theta=0.3, vertex=np.array([0.5, 0.6]))
    x = np.linspace(-0.15, 0.25, 25)
    c, s = np.cos(par.theta), np.sin(par.theta)
    p = par.vertex + np.c_[c * x - s * par.a * x * x, s * x + c * par.a * x * x] + 1e-4 * rng.standard_normal((25, 2))
    fit = fit_parabola(p, par, max_nfev=200)
    q = np.r_[np.log(fit.parabola.a), fit.parabola.theta, fit.parabola.vertex]
    G = parabola_weights(fit.parabola, p)
    dp = 1e-6 * rng.standard_normal((25, 2))
    moved = fit_parabola(p + dp, fit.parabola, max_nfev=200)
    dq = np.r_[np.log(moved.parabola.a), moved.parabola.theta, moved.parabola.vertex] - q
    # Gauss-Newton's J^T J drops the residuals' curvature term: measured
    # within 0.5% here (residuals of 1e-4 m).
    assert np.allclose(dq, np.einsum("aij,ij->a", G, dp), rtol=1e-2, atol=1e-10)


def test_paper_parabola_errors_cover_on_ar1_tracks():
    # The parabola method's (log a, theta, vertex) are under the error model
    # the end points use (AR(1), the MLE's scale; recover.paper
    # .parabola_inputs_covariance).  sliding_tracks(30, 1, rho=0.8): its 9
    # parabola answers measured RMS error 3.45 stated with the fit's own
    # covariance (independent frames), 1.59 with the shared model (60
    # tracks: 3.33 -> 1.37, the MLE's 1.01).
    from cuespin.recover.estimate import estimate
    from cuespin.recover.simulate import sliding_tracks
    zs = []
    for tr in sliding_tracks(30, 1, rho=0.8):
        est = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s)
        pp = est.paper
        if pp is not None and pp.status == "ok" and pp.stderr and pp.trajectory == "parabola":
            zs.append((np.r_[pp.v0, pp.w0] - np.r_[tr.shot.v0, tr.shot.w0]) / np.r_[pp.stderr["v0"], pp.stderr["w0"]])
    z = np.ravel(zs)
    assert len(zs) >= 6 and np.sqrt(np.mean(z * z)) < 2.5, (len(zs), np.sqrt(np.mean(z * z)))


def paper_coverage(n, seed, lossless=True):
    """The paper's answers' components (v0, w0) within 1.96 stated errors,
    and their RMS error in stated errors, on ``n`` simulated sliding tracks."""
    from cuespin.recover.simulate import sliding_tracks
    zs = []
    for tr in sliding_tracks(n, seed):
        pp = recover_track(tr.t, tr.xy, np.ones(len(tr.t), bool), np.full(len(tr.t), tr.sigma), tr.params,
                           tr.exposure_s, "all", lossless=lossless)["methods"]["paper"]
        if pp["status"] == "ok" and pp.get("stderr"):
            zs.append((np.r_[pp["v0"], pp["w0"]] - np.r_[tr.shot.v0, tr.shot.w0])
                      / np.r_[pp["stderr"]["v0"], pp["stderr"]["w0"]])
    z = np.ravel(zs)
    return int(np.sum(np.abs(z) < 1.96)), len(z), float(np.sqrt(np.mean(z * z)))


@pytest.mark.slow
def test_paper_coverage_on_simulated_sliding_tracks():
    # Issue 11: the paper's stated errors cover its errors 90-97% of the
    # time.  Simulated sliding tracks (recover.simulate.sliding_tracks: the
    # sampler's presets over the frame-rate and noise grid, each frame's
    # error exactly independent), every ok answer's four components within
    # 1.96 stated errors: seed 1 measured 257 of 284 (90.5%, 71 answers of
    # 200 tracks; RMS error 1.07 stated; 92.6%, 0.98 with the parabola fit
    # capped), seed 2 272 of 288 (94.4%).  Held within 3 binomial standard
    # errors of 95% over the answers, not the components: an answer's four
    # are strongly correlated (benchmarks/accuracy.py's intervals).
    hit, n, rms = paper_coverage(200, 1)
    margin = 3 * np.sqrt(0.95 * 0.05 / (n / 4))
    assert n >= 200 and abs(hit / n - 0.95) < margin, (hit, n, rms)


def test_codec_error_in_pixels_through_the_camera():
    # A codec's error lives in the image: one variance in px^2, seen on the
    # table through the camera's Jacobian at each frame (issue 11).  Under a
    # 15-degree tilt from 1.5 m the scale varies across the table; a track
    # given stated errors of 0.02 px plus a codec's 0.05 px (isotropic in
    # pixels) gives back 0.05 px (precision ~2.5% as above; within 10%).
    from cuespin.physics.camera import pinhole_camera
    from cuespin.recover.measurements import pixel_to_table, table_covariance
    shot, p = sample_shot(3, "random")
    ph = phases(shot, p)
    cam = pinhole_camera(height_m=1.5, tilt_deg=15.0, R=p.R, fps=120.0)
    t = np.arange(0.0, min(ph.t2 + 0.3, 5.0), 1 / 120.0)
    truth = model_track(shot, p, t)
    stated_px, codec_px = 0.02, 0.05
    rng = np.random.default_rng(11)
    uv = cam.to_pixels(truth) + np.hypot(stated_px, codec_px) * rng.standard_normal((len(t), 2))
    xy = cam.to_table(uv)
    cov = table_covariance(cam, xy, np.full((len(t), 2), stated_px))
    B = pixel_to_table(cam, xy)
    scale = np.sqrt(np.abs(np.linalg.det(B)))
    assert scale.max() / scale.min() > 1.05  # the scale varies along this path
    out, est = recover_track(t, xy, np.ones(len(t), bool), cov, p, lossless=False, px_to_m=B,
                             return_estimate=True)
    mle = out["methods"]["mle"]
    assert mle["status"] == "ok", mle["reason"]
    assert mle["codec_noise_px"] == pytest.approx(codec_px, rel=0.1)
    assert 0.9 < mle["chi2_per_dof"] < 1.1
    # Each frame's weight: the stated covariance plus codec_px^2 B B^T.
    k = 40
    want = cov[k] + mle["codec_noise_px"] ** 2 * B[k] @ B[k].T
    assert np.allclose(est.meas.cov[k], want, rtol=1e-9)


def test_paper_line_refuses_a_bending_path():
    # A slide of 4 frames at 60 fps (too short to test for a parabola) whose
    # side spin bends the path (benchmarks/accuracy.py MJPG shot 36): x1
    # lies 5.5 mm off the line from x0 to x2; the line method answered 1300
    # stated errors off before it was asked to check.  Now: failed, saying why.
    from cuespin.physics.motion import BallParams, Shot
    p = BallParams(R=0.028575, mu_s=0.294, mu_r=0.0182)
    shot = Shot(x0=(2.2, 0.97), v0=(-0.35, -0.031), w0=(-12.97, 8.32), t0=0.124)
    tr = simulate_track(shot, p, 60.0, 1e-5, 0, t_end=phases(shot, p).t2 + 0.3)
    pp = recover_track(tr.t, tr.xy, np.ones(len(tr.t), bool), np.full(len(tr.t), 1e-5), p)["methods"]["paper"]
    assert pp["status"] == "failed" and "not straight" in pp["reason"], pp


def test_codec_share_solves_the_weighted_moment_equation_with_its_floor():
    # The codec's share is solved on the covariances the fit then uses
    # (Measurements.with_codec, floor included): the weighted residuals
    # match the degrees of freedom exactly, also when a negative share puts
    # some frames on their floor (the stated errors vary 1-6x along the
    # track, and a tilted camera's metres per pixel are correlated in x, y;
    # before, the share stopped where the smallest stated error reached its
    # floor: residuals at 0.6 and 0.8 of the stated gave 112 and 183 for 235).
    from cuespin.recover.measurements import MIN_NOISE_FRACTION, codec_excess
    rng = np.random.default_rng(3)
    n = 120
    t = np.arange(n) / 120.0
    se = 1e-4 * np.exp(rng.uniform(0, np.log(6), n))
    B = np.array([[2e-3, 4e-4], [-3e-4, 1.6e-3]]) * (1 + 0.3 * rng.random((n, 1, 1)))
    meas = build_measurements(t, np.zeros((n, 2)), se, px_to_m=B)
    for shrink in (0.6, 0.8, 1.0, 1.5):  # residuals smaller and larger than stated
        raw = shrink * se[:, None] * rng.standard_normal((n, 2))
        r = meas.whiten(-raw)
        c = codec_excess(meas, r, 5)
        w = meas.with_codec(c).whiten(-raw)
        floored = int(np.sum(c < meas.codec_floor()))
        left = meas.with_codec(c).cov - MIN_NOISE_FRACTION**2 * meas.cov  # at or above the floor
        assert np.linalg.eigvalsh(left).min() > -1e-12 * meas.cov.max()
        assert np.sum(w * w) == pytest.approx(meas.dof(5), rel=1e-6), (shrink, c, floored)
        if shrink == 0.6:
            assert floored > 0  # the floor is in play


def test_sliding_seen_in_too_few_frames_is_degenerate():
    # A slip lasting 1.5 frames at 120 fps (benchmarks/short_slide.py: seen
    # in 1-2 measured frames the intervals covered 80-86%, RMS 1.9-2.3
    # stated errors): degenerate, never ok with errors that do not hold.
    from cuespin.physics.motion import Shot, z_cross
    from cuespin.recover.estimate import estimate
    rng = np.random.default_rng(0)
    shot, p = sample_shot(rng, "case4")
    u0 = 3.5 * p.mu_s * p.g * (1.5 / 120.0) * np.array([0.6, 0.8])
    v0 = np.asarray(shot.v0, float)
    s = Shot(x0=shot.x0, v0=v0, w0=z_cross(v0 - u0) / p.R, t0=shot.t0)
    tr = simulate_track(s, p, 120.0, 2e-5, rng)
    m = estimate(tr.t, tr.xy, np.full(len(tr.t), 2e-5), p, 0.0, run_paper=False).mle
    assert m.status == "degenerate" and "at least 3 frames needed" in m.reason


def test_frames_at_one_place_on_the_image_share_a_codec_error():
    # Frames showing the ball within a fraction of a pixel of each other
    # (a ball creeping to its stop) are paired with their kernel; with
    # residuals that share an error across those pairs the measured r0 is
    # positive and the sandwich widens v0's error; residuals with no such
    # sharing leave it as it was.
    from types import SimpleNamespace

    from cuespin.recover.mle import still_codec_pairs, still_codec_r0, still_codec_sandwich
    rng = np.random.default_rng(1)
    n = 200
    t = np.arange(n) / 240.0
    x = 0.4 * (1 - np.exp(-t / 0.2))  # slows to a creep: the last frames within 0.1 px
    xy = np.stack([x, np.zeros(n)], 1)
    B = np.broadcast_to(np.eye(2) / 500.0, (n, 2, 2))
    meas = build_measurements(t, xy, 2e-5, px_to_m=B)
    i, j, k = still_codec_pairs(meas)
    assert len(i) > 20 and np.all((k > 0) & (k <= 1))
    J = np.zeros((2 * n, 3))  # whitened Jacobian of (x0, v0 along x, y0)
    J[0::2, 0], J[0::2, 1], J[1::2, 2] = 1.0, t / 0.01, 1.0
    shared = np.repeat(rng.standard_normal(n // 10), 10)  # runs of 10 frames share one error
    for r, widens in ((np.stack([shared, shared], 1) * 0.85 + 0.5 * rng.standard_normal((n, 2)), True),
                      (rng.standard_normal((n, 2)), False)):
        fit = SimpleNamespace(jac=J, residuals=r)
        r0 = still_codec_r0(r, i, j, k)
        wide = still_codec_sandwich(fit, meas)
        base = np.linalg.inv(J.T @ J)
        assert (r0 > 0.15) == widens, r0
        if widens:
            assert wide[1, 1] > 1.1 * base[1, 1]


def test_stop_shot_w0_error_from_the_profile_likelihood():
    # Struck with the back spin that stops the ball as sliding ends
    # (R|w0| = 2.5|v0|): the track moves only by the square of a change of
    # the slip's size, so the Jacobian's error is no interval (it put R w0
    # 3.3 errors off on seed 2); the profile likelihood's holds the error.
    from cuespin.physics.motion import BallParams, Shot
    from cuespin.recover.estimate import estimate
    p = BallParams()
    shot = Shot(x0=np.array([1.0, 0.7]), v0=np.array([1.0, 0.0]), w0=np.array([0.0, -2.5 / p.R]), t0=0.3)
    for seed in (1, 2):
        tr = simulate_track(shot, p, 240.0, 1e-4, np.random.default_rng(seed), t_end=phases(shot, p).t2 + 0.5)
        m = estimate(tr.t, tr.xy, np.full(len(tr.t), 1e-4), p, 0.0, run_paper=False).mle
        assert m.status == "ok" and m.model == "full"
        z = (m.w0 - shot.w0) / m.stderr["w0"]
        assert np.all(np.abs(z) < 1.96), (seed, z)


def test_lossy_rest_shares_at_least_its_floor():
    # A lossy codec's rest: identical frames share their whole error (one
    # frame's covariance, as before); frames scattering as much as stated
    # (high noise) share SHARED_REST_MIN_SHARE of it beyond the scatter rule
    # (measured against the truth on MJPG rests at noise 3-11: 0.061; one
    # frame's covariance stated them 13 times their error).
    from cuespin.recover.measurements import SHARED_REST_MIN_SHARE

    def lossy_rest_variance(xy_rest):
        n = len(xy_rest)
        t = np.arange(n + 30) / 100.0
        xy = np.vstack([xy_rest, np.c_[np.linspace(0.01, 0.3, 30), np.zeros(30)]])
        m = build_measurements(t, xy, np.full(len(t), SIGMA), t0=(n + 0.5) / 100.0, exposure_s=0.005,
                               frame_dt=0.01, shared_rest=True)
        assert np.bincount(m.group[m.used])[0] >= n - 1              # the rest one measurement
        return np.diag(np.linalg.inv(m.W[0] @ m.W[0].T)) / SIGMA**2

    assert lossy_rest_variance(np.full((40, 2), 1e-5)) == pytest.approx([1.0, 1.0])
    # Scatter well above the stated error: only the floor is shared.
    wide = 2.0 * SIGMA * np.random.default_rng(4).standard_normal((40, 2))
    assert lossy_rest_variance(wide) == pytest.approx([SHARED_REST_MIN_SHARE + (1 - SHARED_REST_MIN_SHARE) / 40] * 2)
    # Fewer than 10 frames: no scatter measured, one frame's covariance.
    assert lossy_rest_variance(wide[:6]) == pytest.approx([1.0, 1.0])


def test_a_lossless_shaded_balls_rest_is_one_frames_error_whatever_its_scatter():
    # A lossless codec's shaded ball (look_rest): the still look's error is
    # the same in every frame of the rest, so its frames' scatter (the
    # sensor's noise alone) does not lower the rest's variance below one
    # frame's stated covariance (LOOK_REST_SHARE 1; measured against the
    # truth on 18 realistic FFV1 renders: the rests' means' squared error
    # 0.87 of one frame's stated variance in median).
    from cuespin.recover.measurements import LOOK_REST_SHARE

    n = 40
    t = np.arange(n + 30) / 100.0
    rest = 2.0 * SIGMA * np.random.default_rng(4).standard_normal((n, 2))   # scatter as independent frames
    xy = np.vstack([rest, np.c_[np.linspace(0.01, 0.3, 30), np.zeros(30)]])

    def rest_variance(**kw):
        m = build_measurements(t, xy, np.full(len(t), SIGMA), t0=(n + 0.5) / 100.0, exposure_s=0.005,
                               frame_dt=0.01, **kw)
        assert np.bincount(m.group[m.used])[0] >= n - 1
        return np.diag(np.linalg.inv(m.W[0] @ m.W[0].T)) / SIGMA**2

    assert rest_variance(shared_rest=True, look_rest=True) == pytest.approx([LOOK_REST_SHARE] * 2)
    assert rest_variance(shared_rest=True)[0] < 0.1                        # the scatter rule's floor


def test_a_shaded_lossy_rest_is_stated_at_least_one_frames_error():
    # A shaded ball at rest on a lossy codec (still_look): the codec's error
    # at its place is the same in every frame (light47, restfloor), so its
    # mean has the still look's STILL_LOOK_VAR_PX2 (px^2 through metres
    # per pixel) beyond the rest's rule and is stated at least one frame's
    # stated covariance, whatever its frames' scatter and whatever the
    # codec's measured excess takes back
    # (a negative with_codec); a rest already stated wider, single frames
    # and tracks without the flag unchanged; a linear estimate's covariance
    # (linear_covariance) carries it as the fit's whitener does.
    from cuespin.recover.measurements import SHARED_REST_MIN_SHARE, STILL_LOOK_VAR_PX2, linear_covariance

    n = 40
    t = np.arange(n + 30) / 100.0
    rest = 2.0 * SIGMA * np.random.default_rng(4).standard_normal((n, 2))  # scatter above the stated error
    xy = np.vstack([rest, np.c_[np.linspace(0.01, 0.3, 30), np.zeros(30)]])
    px_to_m = np.broadcast_to(np.diag([3e-3, 2e-3]), (len(t), 2, 2))  # 333 and 500 px/m

    def meas(**kw):
        return build_measurements(t, xy, np.full(len(t), SIGMA), t0=(n + 0.5) / 100.0, exposure_s=0.005,
                                  frame_dt=0.01, shared_rest=True, px_to_m=px_to_m, **kw)

    def cov(m):
        return np.linalg.inv(np.swapaxes(m.W, -1, -2) @ m.W)

    old, new = meas(), meas(still_look=True)
    one = SIGMA**2 * np.eye(2)
    look = STILL_LOOK_VAR_PX2 * np.diag([3e-3, 2e-3]) ** 2                # the still look's, kept inside

    def floored(base):  # both diagonal: the Loewner order's least cover is the larger per axis
        return np.diag(np.maximum(np.diag(base + look), SIGMA**2))

    assert cov(old)[0] == pytest.approx((SHARED_REST_MIN_SHARE + (1 - SHARED_REST_MIN_SHARE) / n) * one, rel=1e-9)
    # x: the look's 0.0135 sigma^2 beyond the rest's own already covers one
    # frame's; y (0.006 sigma^2 of look) is raised to it.
    assert cov(new)[0] == pytest.approx(floored(cov(old)[0]), rel=1e-9)
    assert cov(new)[0][1, 1] == pytest.approx(SIGMA**2, rel=1e-9) and cov(new)[0][0, 0] > 1.4 * SIGMA**2
    assert cov(new)[1:] == pytest.approx(cov(old)[1:], rel=1e-12)
    # A negative codec excess shrinks the frames, not the rest's floor; a
    # positive one beyond it widens the rest as before.
    px2 = -0.5 * SIGMA**2 / 3e-3**2
    assert cov(new.with_codec(px2))[0] == pytest.approx(floored(cov(old.with_codec(px2))[0]), rel=1e-9)
    assert cov(new.with_codec(px2))[1:] == pytest.approx(cov(old.with_codec(px2))[1:], rel=1e-12)
    big = 30.0 * SIGMA**2 / 3e-3**2
    assert cov(new.with_codec(big))[0] == pytest.approx(cov(old.with_codec(big))[0] + look, rel=1e-9)
    # The rest's mean as a linear estimate: its covariance is the whitener's.
    w = np.zeros((1, len(t)))
    w[0, new.group == 0] = 1.0 / np.sum(new.group == 0)
    assert linear_covariance(new, w) == pytest.approx(cov(new)[0], rel=1e-9)
    assert linear_covariance(new.with_codec(px2), w) == pytest.approx(cov(new.with_codec(px2))[0], rel=1e-9)


def test_x0_states_the_strike_times_own_error():
    # fit.segment._geometry_cov: x0 is the fitted path at t0, so t0's own
    # error (the profile Hessian's, as t1's moves x1) moves it along v0
    # (x0_t0).  Frames exactly independent at the stated sigma: x0's error
    # against the truth in its stated covariance, mean squared per axis,
    # on sliding_tracks(30, 1)'s 8 ok paper answers: 2.98 without t0's
    # share, 0.79 with it (60 tracks: 3.30 -> 0.92).  Held under 2 (1 if
    # honest; about 0.35 its standard error over 8 answers).
    from cuespin.physics.motion import phases
    from cuespin.recover.estimate import estimate
    from cuespin.recover.paper import geometry_covariance
    from cuespin.recover.simulate import sliding_tracks
    z2 = []
    for tr in sliding_tracks(30, 1):
        est = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s)
        if est.paper is None or est.paper.status != "ok":
            continue
        C = geometry_covariance(est.seg, tr.sigma, True, est.meas)[0:2, 0:2]
        d = np.asarray(est.seg.x0) - phases(tr.shot, tr.params).x0
        z2.append(float(d @ np.linalg.solve(C, d)) / 2)
    assert len(z2) >= 6 and np.mean(z2) < 2.0, (len(z2), np.mean(z2))


def _sampled_track(noise_seed: int):
    """Random shot 5 at 240 fps to 0.3 s past its rest, independent errors
    SIGMA (m) drawn with ``noise_seed``, every frame's covariance SIGMA^2 I."""
    shot, p = sample_shot(5, "random")
    ph = phases(shot, p)
    t = np.arange(0.0, min(ph.t2 + 0.3, 4.0), 1 / 240)
    rng = np.random.default_rng(noise_seed)
    xy = model_track(shot, p, t) + SIGMA * rng.standard_normal((len(t), 2))
    return shot, p, t, xy, np.tile(np.eye(2) * SIGMA**2, (len(t), 1, 1))


def test_frames_without_a_stated_error_are_left_out_not_fitted():
    # A frame whose covariance is indefinite, zero or NaN states no error:
    # recover_track leaves it out as it leaves out a frame without a centre
    # (before, the measurements' Cholesky raised on such a frame: a tracker's
    # relearnt fits, seed 22 realistic shot 16, FFV1), and the answer is the
    # one with those frames masked, to the bit.
    shot, p, t, xy, cov = _sampled_track(1)
    bad = [20, 21, len(t) // 2, len(t) // 2 + 7]
    cov[bad[0]] = [[SIGMA**2, 0.0], [0.0, -SIGMA**2]]  # a negative variance
    cov[bad[1]] = [[1e10, 2e10], [2e10, 1e10]]  # indefinite
    cov[bad[2]] = 0.0
    cov[bad[3]] = np.nan
    assert stated_frames(cov).sum() == len(t) - len(bad)
    got = recover_track(t, xy, np.ones(len(t), bool), cov, p)
    ok = np.ones(len(t), bool)
    ok[bad] = False
    want = recover_track(t, xy, ok, cov, p)
    for m in ("mle", "paper"):
        assert got["methods"][m]["status"] == want["methods"][m]["status"]
        assert got["methods"][m]["v0"] == want["methods"][m]["v0"] and got["methods"][m]["w0"] == want["methods"][m]["w0"]
    assert got["methods"]["mle"]["status"] == "ok"


def test_group_sums_are_add_at_sums():
    # group_shares' mean covariances (bincount's sums, each in frame order
    # from zero) are np.add.at's numbers to the last bit: the fits' answers
    # were kept bit for bit.
    from cuespin.recover.measurements import group_shares
    rng = np.random.default_rng(3)
    g = np.sort(rng.integers(0, 40, 300))
    g = np.unique(g, return_inverse=True)[1]
    m = int(g.max()) + 1
    a = rng.standard_normal((300, 2, 2)) * 1e-5
    cov = a @ np.swapaxes(a, 1, 2) + 1e-12 * np.eye(2)
    c, _ = group_shares(cov, g, m, np.full((m, 2, 2), np.nan))
    ref = np.zeros((m, 2, 2))
    np.add.at(ref, g, cov)
    ref /= np.maximum(np.bincount(g, minlength=m), 1)[:, None, None]
    assert np.array_equal(c, ref)


@pytest.mark.parametrize("fps", [240.0, 480.0])
def test_the_look_factor_comes_off_the_recoverys_rest_only(fps):
    # One rule says what is still (review 11b): the tracker puts the look's
    # factor on every frame (TrackResult.look_factor) and the recovery takes
    # it off exactly the frames of the rests it groups (t0, seg.t2), never a
    # decelerating ball's frames before the segmentation's stop.  The rule
    # it replaced (0.3 px between neighbours) took it off the last 4.8 s of
    # a roll at 480 fps, 2.4 s at 240 fps.
    from cuespin.fit.segment import REST_SIGMAS
    from cuespin.physics import BallParams, Shot
    from cuespin.recover.estimate import estimate

    p = BallParams(mu_r=0.01)
    v = 0.3  # m/s, rolling from the strike: 4.3 s to rest
    shot = Shot(x0=(0.3, 0.5), v0=(v, 0.0), w0=(0.0, v / p.R), t0=0.0)
    t2 = phases(shot, p).t2
    sigma, factor = 1.2e-4, 9.0  # 0.05 px at 2.4 mm/px; a realistic look's factor
    tr = simulate_track(shot, p, fps, sigma, 0, t_start=-0.1, t_end=t2 + 0.3)
    stated = sigma * np.sqrt(factor)
    est = estimate(tr.t, tr.xy, np.full(len(tr.t), stated), p, 0.0, lossless=True, independent=False,
                   look_factor=factor, run_paper=False)
    meas = est.meas
    off = np.isclose(meas.cov[:, 0, 0], sigma**2)
    rest = np.bincount(meas.group[meas.group >= 0], minlength=meas.group.max() + 1)[meas.group] > 1
    rest[meas.group < 0] = False
    np.testing.assert_array_equal(off, rest)
    assert off[tr.t < 0].any() and off[tr.t > t2].any()
    # A moving frame in the rest only as the segmentation calls it: within
    # REST_SIGMAS of its stated error (the factor's) of the final position.
    end = model_track(shot, p, np.array([t2 + 1.0]), 0.0)[0]
    dist = np.hypot(*(model_track(shot, p, tr.t, 0.0) - end).T)
    moving = (tr.t > shot.t0) & (tr.t < t2)
    assert np.all(dist[off & moving] <= REST_SIGMAS * stated)
    # the segmentation's stop early by 0.11-0.17 s (seeds 0-2, 240 and 480 fps)
    assert np.all(tr.t[off & moving] > t2 - 0.25)


def _singular_frames_track():
    """A lossy track with seed 45 shot 28's defect (realistic MJPG, case 4):
    frames whose stated covariance is the inverse of a near-singular normal
    matrix, condition 1e14-1e16, and one stating 5e9 m (eigenvalues as the
    tracker's jackknife gave them there, in units of one frame's variance)."""
    shot, p, t, xy, cov = _sampled_track(2)
    bad = [30, len(t) // 3, len(t) // 2, len(t) // 2 + 9]
    u = np.array([0.6, 0.8])
    for i, big in zip(bad[:3], (1e14, 4e15, 1.1e16)):      # a tiny error across, a huge one along u
        cov[i] = SIGMA**2 * (np.eye(2) + (big - 1.0) * np.outer(u, u))
    cov[bad[3]] = np.eye(2) * 5e9**2                        # well conditioned, the table's size many times over
    return shot, p, t, xy, cov, bad


def test_a_numerically_singular_stated_error_is_left_out_not_weighted():
    # Realistic MJPG seed 45 shot 28 crashed the recovery: its singular
    # frames' codec floor (-3.2e22 px^2) cancelled `cov + floor K` to a zero
    # eigenvalue and codec_excess's Cholesky raised (crash28).  Such frames
    # state no error (stated_frames: MAX_COV_CONDITION, MAX_STATED_SD_M):
    # the answer is the one with them masked, to the bit.
    shot, p, t, xy, cov, bad = _singular_frames_track()
    assert np.flatnonzero(~stated_frames(cov)).tolist() == bad
    got = recover_track(t, xy, np.ones(len(t), bool), cov, p, lossless=False)
    ok = np.ones(len(t), bool)
    ok[bad] = False
    want = recover_track(t, xy, ok, cov, p, lossless=False)
    for m in ("mle", "paper"):
        assert got["methods"][m]["status"] == want["methods"][m]["status"]
        assert got["methods"][m]["v0"] == want["methods"][m]["v0"] and got["methods"][m]["w0"] == want["methods"][m]["w0"]
    assert got["methods"]["mle"]["status"] == "ok", got["methods"]["mle"]["reason"]


def test_codec_excess_answers_on_measurements_whose_floor_cancels():
    # codec_excess on measurements built with the singular frames kept (a
    # caller past stated_frames): the bracket's low end, every frame on its
    # floor, is no covariance in rounding; the solver starts from the lowest
    # valid codec variance instead and answers a number, never raises.
    from cuespin.recover.measurements import codec_excess
    shot, p, t, xy, cov, bad = _singular_frames_track()
    # A tilted camera's metres per pixel, 5% apart from frame to frame (its
    # generalised eigenvalues' rounding is what cancels; with the identity
    # the old bracket happened to hold).
    B = np.array([[2.5e-3, 0.3e-3], [0.1e-3, 2.2e-3]])
    B = B * (1 + 0.05 * np.random.default_rng(0).standard_normal((len(t), 1, 1)))
    meas = build_measurements(t, xy, cov, px_to_m=B)
    r = meas.whiten(model_track(shot, p, meas.t_used))
    c = codec_excess(meas, r, 7)
    assert np.isfinite(c)
    meas.with_codec(c)                                      # a covariance the fit can factor


def test_a_track_whose_errors_are_not_calibrated_answers_nothing_ok():
    # A 4:1:1 / 4:1:0 track states its errors uncalibrated (TrackResult
    # .warning; measured error / stated 0.4-3.7, fix411): the same track that
    # is answered ok by both methods is then degenerate with that reason, its
    # numbers kept, and no best (review of fix411, MUST-FIX 1).
    shot, p = sample_shot(3, "random")
    ph = phases(shot, p)
    tr = simulate_track(shot, p, 120.0, SIGMA, 4, t_end=ph.t2 + 0.3)
    args = (tr.t, tr.xy, np.ones(len(tr.t), bool), np.full(len(tr.t), SIGMA), p)
    plain = recover_track(*args)
    assert plain["best"] is not None
    why = "stated errors not calibrated: the video's yuv411p chroma is shared over 4 x 1 pixels"
    out = recover_track(*args, uncalibrated=why)
    assert out["best"] is None
    for name, m in out["methods"].items():
        assert m["status"] != "ok", name
        if plain["methods"][name]["status"] == "ok":
            assert m["status"] == "degenerate" and why in m["reason"]
            assert m["v0"] == plain["methods"][name]["v0"]


def test_bound_whitens_a_codecs_correlation_axis_by_axis_as_the_whole_factor_does():
    # crb_jacobian whitens the time correlation C = I + R (x) I_2 of the rows
    # (m, 2) by L (x) I_2, L the (m, m) Cholesky factor of I + R: the same
    # factor as the (2m, 2m) one, in 8 times fewer operations (recspeed).
    # Tolerance: rounding of the two factorisations' sums (measured <= 2e-15
    # on J's entries, 1.3e-12 on the bound's numbers on 80 H.264 tracks).
    from scipy.linalg import cholesky, solve_triangular

    from cuespin.recover.mle import INTER_CODEC_ACF, crb_jacobian, shared_rho

    shot, p = sample_shot(7, "random")
    t = np.arange(0.0, 1.0, 1 / 120)
    meas = build_measurements(t, model_track(shot, p, t), np.full(len(t), SIGMA), t0=shot.t0, frame_dt=1 / 120)
    J = crb_jacobian(shot, p, meas, acf=INTER_CODEC_ACF)
    plain = crb_jacobian(shot, p, meas)
    m = meas.n
    R = np.zeros((m, m))
    single = np.flatnonzero(meas.single)
    R[np.ix_(single, single)] = shared_rho(meas, INTER_CODEC_ACF)
    whole = solve_triangular(cholesky(np.eye(2 * m) + np.kron(R, np.eye(2)), lower=True), plain, lower=True)
    assert single.size > 50 and J.shape == whole.shape == (2 * m, 7)
    np.testing.assert_allclose(J, whole, rtol=0, atol=1e-12 * np.abs(whole).max())
