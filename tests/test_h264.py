"""H.264's error is shared between frames: the maximum-likelihood fit's
standard errors must still be honest (errors of about one stated standard
error, RMS) on H.264 as on MJPG."""

from __future__ import annotations

import dataclasses
from fractions import Fraction

import numpy as np
import pytest
from scipy.stats import chi2

from cuespin.data_gen.sampler import sample_scene
from cuespin.pipeline.run import run_recover
from cuespin.recover.estimate import estimate
from cuespin.recover.mle import model_track
from cuespin.recover.simulate import shared_errors, sliding_tracks
from cuespin.render.video import render_video
from cuespin.track.reader import VideoInfo


def info(codec, lossless=False):
    return VideoInfo(width=64, height=32, n_frames=10, codec=codec, pix_fmt="yuv420p", lossless=lossless,
                     time_base=Fraction(1, 90000), backend="av")


def test_which_codecs_predict_between_frames():
    assert info("h264").inter_frame and info("hevc").inter_frame
    assert not info("mjpeg").inter_frame and not info("MJPG").inter_frame  # FFmpeg's name and OpenCV's FourCC
    assert not info("ffv1", lossless=True).inter_frame


def rms_bound(n_values: int, level: float = 1e-3) -> float:
    """RMS of ``n_values`` standard normals stays below this but with probability ``level``."""
    return float(np.sqrt(chi2.isf(level, n_values) / n_values))


def z_of(m, shot) -> np.ndarray:
    return np.r_[(m.v0 - shot.v0) / m.stderr["v0"], (m.w0 - shot.w0) / m.stderr["w0"]]


def test_correlated_codec_error_is_in_the_standard_errors():
    """Simulated tracks with an error of the measured H.264 kind (a part the
    tracker states plus the codec's, 3 times its variance, as measured on
    H.264 at CRF 20: README; the whole error correlated between frames dt
    apart as recover.mle.INTER_CODEC_ACF says): with the inter-frame model
    the errors are about one stated standard error; treated as independent
    they are not."""
    rng = np.random.default_rng(7)
    z = {True: [], False: []}
    # 11: the 12th (v0 0.23 m/s at 120 fps) ends at a wrong optimum with
    # either treatment (errors of hundreds of standard errors): another matter.
    for tr in sliding_tracks(11, seed=3, presets=("case3", "random"), fps_grid=(60.0, 120.0),
                             sigma_grid=(1e-4,), blur=False):
        n = len(tr.t)
        # The whole error, 4 sigma^2 (the stated sigma^2 and the codec's 3),
        # correlated in time, on the track's exact centres.
        err = 2.0 * tr.sigma * shared_errors(n, tr.fps, rng)
        xy = model_track(tr.shot, tr.params, tr.t, tr.exposure_s)
        for inter in (True, False):
            m = estimate(tr.t, xy + err, np.full(n, tr.sigma), tr.params, lossless=False,
                         run_paper=False, inter_frame=inter).mle
            if m.status == "ok":
                z[inter].append(z_of(m, tr.shot))
    on, off = np.concatenate(z[True]), np.concatenate(z[False])
    assert len(z[True]) >= 8
    assert np.sqrt(np.mean(on**2)) < rms_bound(len(on))
    assert np.sqrt(np.mean(on**2)) > 0.5  # not merely wide
    # Measured (h264cov's INTER_CODEC_ACF): RMS 0.96 with the model (coverage
    # 95.5%), 1.39 without (84.1%); before it (frames, the codec's share
    # only): 1.05 and 1.73.
    assert np.sqrt(np.mean(off**2)) > 1.2 * np.sqrt(np.mean(on**2))


def test_codec_variance_measured_with_the_shared_error():
    """The codec's variance the first fit measures (recover.mle.correlated_codec_var)
    on tracks whose whole error (the stated sigma^2 and a codec's 3 sigma^2) is
    correlated in time as INTER_CODEC_ACF says: near the truth although the fit
    absorbs part of it.  Measured on 24 such tracks (seed 4, 60-240 fps): mean
    ratio 0.946 (s.e. 0.020); these 12: 0.976; the estimator before h264cov
    (only the codec's share correlated) 0.823 on the 24, 0.853 on these 12."""
    rng = np.random.default_rng(11)
    ratios = []
    for tr in sliding_tracks(12, seed=4, presets=("case3", "random"), fps_grid=(60.0, 120.0, 240.0),
                             sigma_grid=(1e-4,), blur=False):
        n = len(tr.t)
        c = 3.0 * tr.sigma**2
        err = np.sqrt(tr.sigma**2 + c) * shared_errors(n, tr.fps, rng)
        est = estimate(tr.t, model_track(tr.shot, tr.params, tr.t, tr.exposure_s) + err, np.full(n, tr.sigma),
                       tr.params, lossless=False, run_paper=False, inter_frame=True)
        ratios.append(est.codec_var / c)
    # The standard error of a 12-track mean: 0.098 / sqrt(12) = 0.028.
    # Above: 2.3 of them over the truth (1), so an unbiased estimator passes
    # too.  Below: 2.3 of them under the estimator's measured mean (0.946,
    # 24 tracks; the fit absorbs part of the shared error), its bias allowed.
    assert 0.88 < np.mean(ratios) < 1.065


def _shared_scale_z(monkeypatch, n_tracks: int, seed: int, drift: float):
    """z of v0 and w0 and v0x's standard error per track answered ok, with
    the track's own shared scale (recover.mle.shared_scale) and without it,
    on sliding tracks whose whole error (4 sigma^2) is correlated as
    INTER_CODEC_ACF says, plus ``drift`` times that variance of an AR(1)
    drift of 0.2 s (the intermediate time scale the pooled correlation
    lacks: a shot's 0.2-0.5 px over 0.1-0.5 s, docs/measurements.md cov11)."""
    from cuespin.recover import mle
    from cuespin.recover.simulate import ar1_errors
    rng = np.random.default_rng(seed)
    own = mle.shared_scale
    z, se = {True: [], False: []}, {True: [], False: []}
    for tr in sliding_tracks(n_tracks, seed=seed, presets=("case3", "random"), fps_grid=(60.0, 120.0, 240.0),
                             sigma_grid=(1e-4,), blur=False):
        n = len(tr.t)
        err = 2.0 * tr.sigma * (shared_errors(n, tr.fps, rng)
                                + np.sqrt(drift) * ar1_errors(n, np.exp(-1.0 / (0.2 * tr.fps)), rng))
        xy = model_track(tr.shot, tr.params, tr.t, tr.exposure_s) + err
        ms = {}
        for on in (True, False):
            monkeypatch.setattr(mle, "shared_scale", own if on else lambda *a, **k: (1.0, float("inf"), 0))
            ms[on] = estimate(tr.t, xy, np.full(n, tr.sigma), tr.params, lossless=False, run_paper=False,
                              inter_frame=True).mle
        # Compared only where both answer with the same model: the scale
        # also divides the slip ratio (slipscale), and since slip2 a ratio
        # carried by one measurement names no slide, so a widened track can
        # answer rolling (seed 4's first 60-fps slide: rolling z 3.2, a cost
        # docs/measurements.md slip2 counts), which says nothing of the scale.
        if ms[True].status == "ok" and ms[False].status == "ok" and ms[True].model == ms[False].model:
            for on in (True, False):
                z[on].append(z_of(ms[on], tr.shot))
                se[on].append(ms[on].stderr["v0"][0])
    monkeypatch.setattr(mle, "shared_scale", own)
    return ({on: np.concatenate(v) for on, v in z.items()}, np.array(se[True]) / np.array(se[False]))


def test_a_tracks_own_drift_widens_its_errors(monkeypatch):
    """A drift the pooled correlation understates (an extra 0.2-s AR(1) of
    the whole error's variance): with the track's own shared scale the
    errors are within their stated size, without it well beyond; where the
    errors are as the model says the scale widens little.  Measured on
    these 8 tracks (7 answering with one model either way since slip2):
    drift RMS z 0.81 with, 1.38 without (ratio 1.70; 0.78, 1.35 on 8); no
    drift: none widened (shared_widening; max(1, ratio) before it: v0's
    stated errors 1.11 times wider), RMS z 1.02 (docs/measurements.md
    fixss: 5% of null tracks widen by design)."""
    z, ratio = _shared_scale_z(monkeypatch, 8, seed=4, drift=1.0)
    rms = {on: float(np.sqrt(np.mean(v**2))) for on, v in z.items()}
    assert len(ratio) >= 6
    assert rms[True] < rms_bound(len(z[True]))
    assert rms[False] > 1.4 * rms[True]
    z, ratio = _shared_scale_z(monkeypatch, 8, seed=4, drift=0.0)
    assert np.mean(ratio) < 1.25  # one track in 8 widened 2.5 times would give 1.07
    assert np.sqrt(np.mean(z[True] ** 2)) > 0.5  # not merely wide


def test_the_papers_errors_widen_with_the_tracks_own_drift(monkeypatch):
    """The paper's inputs are measured by the same frames as the fit: when
    the track's own shared scale widens the fit's errors (a drift the
    pooled correlation understates), it widens the paper's by the same
    factor (recover.mle.MLEResult.error_scale, recover.estimate.mle_noise).
    Before, the paper took max(1, chi2/dof) only (1.02 on this track since
    chi2h counted its degrees of freedom under the codec's correlation,
    recover.mle.fit_dof; 0.77 before, so 1): on the first track of seed 4
    with an extra 0.2-s drift that the paper answers, the scale is 2.64 and
    the paper's v0 errors 1.604-1.606 times wider with it than with
    chi2/dof's 1.024 alone (sqrt(2.64 / 1.024) = 1.607)."""
    from cuespin.recover import mle
    from cuespin.recover.estimate import mle_noise
    from cuespin.recover.simulate import ar1_errors
    rng = np.random.default_rng(4)
    own = mle.shared_scale
    for tr in sliding_tracks(8, seed=4, presets=("case3", "random"), fps_grid=(60.0, 120.0, 240.0),
                             sigma_grid=(1e-4,), blur=False):
        n = len(tr.t)
        err = 2.0 * tr.sigma * (shared_errors(n, tr.fps, rng) + ar1_errors(n, np.exp(-1.0 / (0.2 * tr.fps)), rng))
        xy = model_track(tr.shot, tr.params, tr.t, tr.exposure_s) + err
        est = {}
        for on in (True, False):
            monkeypatch.setattr(mle, "shared_scale", own if on else lambda *a, **k: (1.0, float("inf"), 0))
            est[on] = estimate(tr.t, xy, np.full(n, tr.sigma), tr.params, lossless=False, inter_frame=True)
        monkeypatch.setattr(mle, "shared_scale", own)
        if est[True].paper.status == "ok" and est[False].paper.status == "ok":
            break
    else:
        pytest.fail("no track the paper answers")
    m, off = est[True].mle, est[False].mle
    # The drift shows; without the rule only chi2/dof (near 1: the codec's
    # variance is measured from the same residuals) widens.
    assert m.error_scale > 2.0 and off.error_scale == max(1.0, off.chi2 / off.dof) < 1.1
    assert mle_noise(m)[1] == m.error_scale
    ratio = np.asarray(est[True].paper.stderr["v0"]) / np.asarray(est[False].paper.stderr["v0"])
    ratio = ratio * np.sqrt(off.error_scale)  # as from 1
    # The frames' share widens by exactly sqrt(scale); the breakpoints' own
    # shares (fit.segment's geometry_cov, from the segmentation's residuals,
    # recover.paper.breakpoint_shares) are not scaled, so the ratio lies just
    # under it: since fixpap refused the earlier track's one-sided edge, the
    # track the loop takes has them at 0.1-0.2% of the ratio (1.6245, 1.6227
    # against 1.6262).  Allowed: up to 1% under, never over.
    assert np.all(ratio <= np.sqrt(m.error_scale) * (1 + 1e-6))
    assert np.all(ratio >= 0.99 * np.sqrt(m.error_scale)), ratio


@pytest.mark.slow
def test_shared_scale_rarely_widens_where_the_model_holds(monkeypatch):
    """Tracks whose whole error (4 sigma^2) is correlated exactly as
    INTER_CODEC_ACF says, clips ending 0.4-1.5 s after the strike (as a
    realistic 1.5-s clip sees the ball): the track's own shared scale
    widens the errors (recover.mle.shared_widening) on about 5% of them,
    the rule's calibration.  Measured (docs/measurements.md fixss): 12 of
    240 such tracks (seed 50; these first 60: 3), 4 of 220 tracks seen to
    2 s (seed 40); max(1, ratio) before it 40-44%.  Asserted: at most 5%
    plus two binomial standard errors of these 60."""
    from cuespin.recover import mle
    own = mle.shared_scale
    seen = []

    def spy(*a, **k):
        out = own(*a, **k)
        seen.append(mle.shared_widening(*out) > 1.0)
        return out
    monkeypatch.setattr(mle, "shared_scale", spy)
    rng = np.random.default_rng(50)
    widened = []
    for tr in sliding_tracks(60, seed=50, presets=("case3", "random"), fps_grid=(60.0, 120.0, 240.0),
                             sigma_grid=(1e-4,), blur=False, seen_s=(0.4, 1.5)):
        n = len(tr.t)
        xy = model_track(tr.shot, tr.params, tr.t, tr.exposure_s) + 2.0 * tr.sigma * shared_errors(n, tr.fps, rng)
        seen.clear()
        estimate(tr.t, xy, np.full(n, tr.sigma), tr.params, lossless=False, run_paper=False, inter_frame=True)
        if seen:
            widened.append(seen[-1])
    assert len(widened) >= 50
    p = 0.05
    assert np.mean(widened) <= p + 2.0 * np.sqrt(p * (1 - p) / len(widened))


@pytest.mark.slow
def test_h264_recovery_errors_within_stated(tmp_path):
    """Rendered shots (benchmarks/h264_honesty.py's, seed 1, the first six),
    in H.264 at CRF 20 and in MJPG: the errors of v0 and w0 over the shots
    answered ok, in units of their stated standard errors, have an RMS below
    the chi-square bound at 0.1% (before the inter-frame model: H.264 2.2-2.8,
    README)."""
    rng = np.random.default_rng(1)
    seeds = [int(rng.integers(2**31)) for _ in range(6)]
    z = {"H264": [], "MJPG": []}
    for i, s in enumerate(seeds):
        for codec, ext in (("H264", "mp4"), ("MJPG", "avi")):
            scene = sample_scene(s, ("case3", "random", "masse")[i % 3], fps=120.0, px_per_m=250.0, noise=3.0,
                                 blur=False, codec=codec)
            scene = dataclasses.replace(scene, render={**scene.render, "max_duration": 3.0})
            video = tmp_path / f"{i}.{ext}"
            render_video(scene, video)
            res, tr = run_recover(video, scene, method="mle", return_track=True)
            assert tr.inter_frame == (codec == "H264")
            m = res["methods"]["mle"]
            if m["status"] == "ok":
                z[codec].append(np.concatenate([(np.array(m[k]) - getattr(scene.truth, k)) / np.array(m["stderr"][k])
                                                for k in ("v0", "w0")]))
    for codec, rows in z.items():
        assert len(rows) >= 3, codec
        r = np.concatenate(rows)
        assert np.sqrt(np.mean(r**2)) < rms_bound(len(r)), (codec, np.round(r, 2))


def test_i420_chroma_is_each_blocks_mean():
    # A colour edge through the middle of each 2 x 2 block: the block's
    # chroma lies halfway between the two colours' (an encoder's
    # downsampling), not at the left one's as OpenCV's conversion takes it;
    # that had moved a ball tracked in a colour channel ~0.5 px on every
    # H.264 render (review7).
    import cv2

    from cuespin.render.video import to_i420

    h, w = 8, 8
    frame = np.zeros((h, w, 3), np.uint8)
    frame[:, 0::2] = (40, 200, 220)  # BGR: yellow, in the even columns
    frame[:, 1::2] = (40, 110, 30)   # green, in the odd ones
    u = to_i420(frame)[h:h + h // 4].ravel()  # the U plane's rows
    left = cv2.cvtColor(np.full((2, 2, 3), (40, 200, 220), np.uint8), cv2.COLOR_BGR2YUV_I420)[2, 0]
    right = cv2.cvtColor(np.full((2, 2, 3), (40, 110, 30), np.uint8), cv2.COLOR_BGR2YUV_I420)[2, 0]
    assert abs(int(left) - int(right)) > 10  # the two colours' chroma differ
    assert np.all(np.abs(u.astype(float) - (int(left) + int(right)) / 2) <= 1.0)


def test_paper_errors_follow_the_codec_correlation(monkeypatch):
    """The paper's method's stated errors on tracks whose whole error is
    correlated in time as INTER_CODEC_ACF says (as the first test draws
    them): propagated under the same correlation as the fit's
    (recover.estimate.mle_noise, recover.measurements.linear_covariance),
    its errors are about one stated error; with every frame independent
    (before paper11) they are not.  Measured on sliding_tracks(90, 6)'s 32
    parabola answers: RMS 0.95 (coverage 98.4%), independent 1.45 (81.2%);
    on (30, 5)'s 12: 1.01 and 1.30; these 16 tracks' 15 answers: 1.09
    (95.0%) and 1.65 (75.0%), 9 s of CPU."""
    import cuespin.recover.estimate as est_module

    rng = np.random.default_rng(5)
    tracks = []
    for tr in sliding_tracks(16, seed=2, presets=("random", "masse"), fps_grid=(60.0, 120.0, 240.0),
                             sigma_grid=(1e-4,), blur=False):
        n = len(tr.t)
        xy = model_track(tr.shot, tr.params, tr.t, tr.exposure_s) + 2.0 * tr.sigma * shared_errors(n, tr.fps, rng)
        tracks.append((tr, xy))
    independent = est_module.mle_noise
    z = {}
    for model in ("correlated", "independent"):
        if model == "independent":
            monkeypatch.setattr(est_module, "mle_noise", lambda mle, codec=None: independent(mle)[:2])
        z[model] = []
        for tr, xy in tracks:
            p = estimate(tr.t, xy, np.full(len(tr.t), tr.sigma), tr.params, lossless=False,
                         inter_frame=True).paper
            if p.status == "ok":
                z[model].append(z_of(p, tr.shot))
    on, off = np.concatenate(z["correlated"]), np.concatenate(z["independent"])
    assert len(z["correlated"]) >= 8
    assert np.sqrt(np.mean(on**2)) < rms_bound(len(on))
    assert np.sqrt(np.mean(on**2)) > 0.5  # not merely wide
    # Measured ratios 1.29, 1.52, 1.53 (the three sets above).
    assert np.sqrt(np.mean(off**2)) > 1.2 * np.sqrt(np.mean(on**2))


def test_a_negative_codec_variance_does_not_shrink_the_stated_errors(monkeypatch):
    """Tracks whose whole error is the stated one, correlated in time as
    INTER_CODEC_ACF says (no codec share): the first fit's codec variance
    comes out negative on some (the fit absorbs part of a shared error), and
    the recovery keeps the stated errors then (0), not less: a negative one
    had shrunk realistic seed 36 shot 5's (H.264, -0.046 px^2, z 5.75;
    docs/measurements.md, chroma36)."""
    from cuespin.recover import estimate as E
    raw = []
    own = E.correlated_codec_var

    def seen(*a, **k):
        raw.append(own(*a, **k))
        return raw[-1]

    monkeypatch.setattr(E, "correlated_codec_var", seen)
    rng = np.random.default_rng(5)
    kept = []
    for tr in sliding_tracks(6, seed=4, presets=("case3", "random"), fps_grid=(60.0, 120.0, 240.0),
                             sigma_grid=(1e-4,), blur=False):
        n = len(tr.t)
        err = tr.sigma * shared_errors(n, tr.fps, rng)
        est = estimate(tr.t, model_track(tr.shot, tr.params, tr.t, tr.exposure_s) + err, np.full(n, tr.sigma),
                       tr.params, lossless=False, run_paper=False, inter_frame=True)
        kept.append(est.codec_var)
    assert min(raw) < 0  # the case arises
    assert min(kept) >= 0.0


def test_chi2_per_dof_counts_the_shared_error_the_fit_takes_up():
    """chi2/dof on an inter-frame codec is read against the chi-square's
    expectation under the errors' correlation in time (recover.mle.fit_dof):
    a fit weighting frames as independent takes up part of a shared error (a
    constant share is a shift of x0), so 2 per measurement less the
    parameters overstates it by about a third and chi2/dof read 0.72 on
    held37's H.264 answers whose true per-frame errors were as stated
    (docs/measurements.md, chi2h).  Simulated tracks whose whole error is
    correlated as INTER_CODEC_ACF says, with a codec share of 3 sigma^2 (the
    first fit measures it) and with none (its variance clipped at 0).
    Measured (24 tracks each, seed 4, 60-240 fps): chi2/dof median 1.010
    (sd 0.011) and 1.000 (sd 0.045, min 0.87); counted 0.766 and 0.753; the
    degrees of freedom 0.730-0.769 of the count.  Intra-frame (MJPG) fits
    keep the count."""
    from cuespin.recover.mle import INTER_CODEC_ACF, crb_jacobian, fit_dof, shared_rho
    rng = np.random.default_rng(11)
    for scale in (2.0, 1.0):
        chi, counted = [], []
        for tr in sliding_tracks(9, seed=4, presets=("case3", "random"), fps_grid=(60.0, 120.0, 240.0),
                                 sigma_grid=(1e-4,), blur=False):
            n = len(tr.t)
            xy = model_track(tr.shot, tr.params, tr.t, tr.exposure_s) + scale * tr.sigma * shared_errors(n, tr.fps, rng)
            est = estimate(tr.t, xy, np.full(n, tr.sigma), tr.params, lossless=False, run_paper=False,
                           inter_frame=True)
            m = est.mle
            assert m.status == "ok"
            count = est.meas.dof(5 if m.model == "rolling" else 7)
            assert 0.70 < m.dof / count < 0.80
            chi.append(m.chi2 / m.dof)
            counted.append(m.chi2 / count)
            # The rule is tr((I - H) C) with C the whitened errors' dense
            # correlation (as crb_jacobian builds it), at the truth's Jacobian;
            # without the correlation in time (acf None), the count.
            meas = est.meas
            J = crb_jacobian(tr.shot, tr.params, meas, tr.exposure_s)
            R = np.zeros((meas.n, meas.n))
            single = np.flatnonzero(meas.single)
            R[np.ix_(single, single)] = shared_rho(meas)
            C = np.eye(2 * meas.n) + np.kron(R, np.eye(2))
            H = J @ np.linalg.solve(J.T @ J, J.T)
            assert fit_dof(meas, J, 7, INTER_CODEC_ACF) == pytest.approx(np.trace(C - H @ C), rel=1e-6)
            assert fit_dof(meas, J, 7) == meas.dof(7)
        assert 0.9 < np.median(chi) < 1.1, (scale, chi)
        assert np.median(counted) < 0.85, (scale, counted)
        assert min(chi) > 0.8, (scale, chi)


def test_an_intra_frame_codecs_degrees_of_freedom_are_counted():
    """MJPG (no correlation in time): the fit's degrees of freedom are 2 per
    measurement less the parameters, a whole number, as before chi2h."""
    tr = next(sliding_tracks(1, seed=4, presets=("case3",), fps_grid=(120.0,), sigma_grid=(1e-4,), blur=False))
    n = len(tr.t)
    rng = np.random.default_rng(3)
    xy = model_track(tr.shot, tr.params, tr.t, tr.exposure_s) + tr.sigma * rng.standard_normal((n, 2))
    est = estimate(tr.t, xy, np.full(n, tr.sigma), tr.params, lossless=False, run_paper=False, inter_frame=False)
    m = est.mle
    assert m.status == "ok"
    assert m.dof == est.meas.dof(5 if m.model == "rolling" else 7)
    assert float(m.dof).is_integer()


def test_a_slide_carried_by_one_measurement_states_the_free_slip_gap():
    """A true 55-ms slide at 60 fps under H.264-like errors with a 0.2-s
    drift (the first track of test_a_tracks_own_drift_widens_its_errors):
    its slip ratio passes only with the one measurement carrying most of it
    (fit.decide.sliding_seen), so the answer is rolling; before the gap to
    the free-slip fit was stated (statistics review of slip2) it was `ok`
    with z (3.18, -1.10, -1.16, -3.33), v0 16% off; with it z (0.92, -0.71,
    -0.72, -0.93).  Asserted: covered at 95% per component (held-out
    realistic H.264 48/22 was the same case, 2.4 stated errors off)."""
    from cuespin.recover.simulate import ar1_errors
    rng = np.random.default_rng(4)
    tr = next(iter(sliding_tracks(8, seed=4, presets=("case3", "random"), fps_grid=(60.0, 120.0, 240.0),
                                  sigma_grid=(1e-4,), blur=False)))
    n = len(tr.t)
    err = 2.0 * tr.sigma * (shared_errors(n, tr.fps, rng) + ar1_errors(n, np.exp(-1.0 / (0.2 * tr.fps)), rng))
    xy = model_track(tr.shot, tr.params, tr.t, tr.exposure_s) + err
    est = estimate(tr.t, xy, np.full(n, tr.sigma), tr.params, lossless=False, run_paper=False, inter_frame=True)
    m = est.mle
    assert m.status == "ok" and m.model == "rolling"
    assert m.verdicts["slip_in_one_measurement"]
    assert np.all(np.abs(z_of(m, tr.shot)) < 1.96), z_of(m, tr.shot)
    # The JSON states the gap it added (docs/output.md, methods.mle.slip_gap).
    from cuespin.recover.api import mle_dict
    gap = mle_dict(est)["slip_gap"]
    assert len(gap) == 4 and np.hypot(*gap[:2]) > 0
