"""The Cramer-Rao bound of the model an answer was given with
(pipeline.measure.answer_bound), on a simulated shot whose brief slide ends
before the first measured moving frame: the answer is "rolling from the
strike", and the free slip's bound at the truth (mle_bound's, before) is
singular there (held37's 38/8 NaN, 38/36 10^4 times too large)."""

import numpy as np

from cuespin.data_gen.sampler import make_scene
from cuespin.physics import phases
from cuespin.physics.motion import BallParams, Shot, z_cross
from cuespin.pipeline.measure import answer_bound
from cuespin.recover.api import recover_track
from cuespin.recover.mle import Z95, model_track

# The simulated track: 60 fps, independent errors of SIGMA_M per axis; the
# strike 2 ms after a frame and a slide of SLIDE_S, over before the next
# frame (16.7 ms on).
FPS, SIGMA_M, SLIDE_S = 60.0, 3e-4, 0.012
# How far the rolling bound's v0 standard deviations, times the fit's error
# factor sqrt(max(1, chi2/dof)), may differ (relative) from the fit's
# stated standard errors less their unseen-slip allowance: measured at most
# 9.8e-5 over the 11 rolling answers of noise seeds 0-11 (seed 8: degenerate)
# (the bound at the rolling parameters nearest the truth, the fit's
# covariance at its estimate); 5 times that.
BOUND_MATCH_RTOL = 5e-4
# The bias of assuming no slip against the slide's change of velocity,
# mu_s g tau1 (eq. 3): measured 1.030 (the rolling fit to the exact path).
BIAS_MATCH_RTOL = 0.05


def _brief_slide():
    p = BallParams()
    v0 = np.array([1.2, 0.3])
    slip = 3.5 * p.mu_s * p.g * SLIDE_S  # |u0| of a slide lasting SLIDE_S: t1 - t0 = 2 |u0| / (7 mu_s g)
    w0 = z_cross(v0) / p.R + np.array([0.3, 1.0]) / np.hypot(0.3, 1.0) * slip / p.R
    return Shot(x0=(0.8, 0.5), v0=tuple(v0), w0=tuple(w0), t0=0.302), p


def test_rolling_answer_bound_on_an_unseen_slide():
    shot, p = _brief_slide()
    assert abs(phases(shot, p).t1 - shot.t0 - SLIDE_S) < 1e-9
    scene = make_scene(shot, p, fps=FPS)
    t = np.arange(0.0, 1.5, 1 / FPS)
    clean = model_track(shot, p, t)
    for seed in range(3):
        noisy = clean + SIGMA_M * np.random.default_rng(seed).standard_normal(clean.shape)
        out, est = recover_track(t, noisy, np.ones(len(t), bool), np.full(len(t), SIGMA_M), p, method="mle",
                                 return_estimate=True)
        m = out["methods"]["mle"]
        assert m["status"] == "ok" and m["model"] == "rolling"
        b = answer_bound(scene, est.meas, "rolling")
        assert b.reason == "" and b.cov is not None and np.all(np.isfinite(b.sd)) and np.all(b.sd > 0)
        # the fit's statistical error: its stated one less the unseen-slip allowance (recover.mle.result)
        stat = np.sqrt(np.square(m["stderr"]["v0"]) - (m["unseen_slip"] / Z95) ** 2)
        factor = np.sqrt(max(1.0, m["chi2_per_dof"]))
        np.testing.assert_allclose(b.sd * factor, stat, rtol=BOUND_MATCH_RTOL)
        # assuming no slip costs mu_s g tau1 of v0, whatever the noise; the answer's allowance covers it
        dv = float(np.hypot(*b.bias[:2]))
        assert abs(dv / (p.mu_s * p.g * SLIDE_S) - 1.0) < BIAS_MATCH_RTOL
        assert m["unseen_slip"] >= dv
        assert np.all(np.isnan(b.z(np.r_[m["v0"], m["w0"]])[2:]))  # a rolling answer's bound is v0's
        # the free slip's bound at the truth: none, and it says why
        f = answer_bound(scene, est.meas, "full")
        assert f.cov is None and "before the first measured moving frame" in f.reason


def test_a_shot_without_a_bound_is_listed_apart(capsys):
    # held37: 38/8's NaN bound was left out of the RMS / bound silently.
    # accuracy.bound_summary averages the shots with a bound (per model)
    # and lists the others with the reason answer_bound gave.
    from benchmarks.accuracy import bound_summary
    nan = float("nan")
    from benchmarks.accuracy import COMPONENTS
    row = dict(mle_crb_z_indep=nan, mle_bias_v0=nan, mle_bound_fail="")

    def shot(i, z, **kw):  # every component z bounds off
        return dict(row, i=i, mle_model="full", mle_crb_z=z, **{f"mle_crb_{c}": z for c in COMPONENTS}, **kw)
    rows = [shot(0, 1.0), shot(1, 3.0), shot(2, nan, mle_bound_fail="the information is singular")]
    bound_summary(rows)
    out = capsys.readouterr().out
    assert f"2 shots): {np.sqrt(5.0):.2f}" in out, out
    assert "no bound on 1 ok answers" in out and "shot 2 (full): the information is singular" in out, out


def test_no_bound_where_the_truth_stops_as_its_slide_ends():
    # The sampler's case2 stops exactly as sliding ends: the truth on the
    # model's kink, where the free slip's bound is not defined (MJPG seed
    # 39 shots 5 and 16, H.264 37/5, 37/27, 38/5, 38/38: their w0 "bounds"
    # 10^4-10^5 times the error, averaged in before).
    from cuespin.data_gen.sampler import sample_shot
    shot, p = sample_shot(3, "case2")
    ph = phases(shot, p)
    assert np.hypot(*ph.v1) < 1e-9
    t = np.arange(0.0, ph.t1 + 0.3, 1 / 120)
    clean = model_track(shot, p, t)
    noisy = clean + SIGMA_M * np.random.default_rng(0).standard_normal(clean.shape)
    _, est = recover_track(t, noisy, np.ones(len(t), bool), np.full(len(t), SIGMA_M), p, method="mle",
                           return_estimate=True)
    b = answer_bound(make_scene(shot, p, fps=120.0), est.meas, "full")
    assert b.cov is None and "stops as its slide ends" in b.reason


def test_the_summary_and_the_intervals_pool_rms_over_bound_alike(capsys):
    # One definition (pipeline.measure.rms_z): bound_summary and intervals
    # pool every covered component, a rolling answer's two (v0) beside a
    # free slip's four; before, the summary took the RMS of the shots' own
    # RMS (held37's seed 37: 1.09 against the intervals' 1.11).
    from benchmarks.accuracy import COMPONENTS, bound_summary, intervals
    nan = float("nan")
    base = dict(mle_status="ok", noise=1.0, chi2_per_dof=1.0, mle_crb_z_indep=nan, mle_bias_v0=nan,
                mle_bound_fail="", **{f"mle_z_{c}": 0.5 for c in COMPONENTS})
    full = dict(base, i=0, mle_model="full", mle_crb_z=1.0, **{f"mle_crb_{c}": 1.0 for c in COMPONENTS})
    rolling = dict(base, i=1, mle_model="rolling", mle_crb_z=3.0,
                   **{f"mle_crb_{c}": z for c, z in zip(COMPONENTS, (3.0, 3.0, nan, nan))})
    pooled = f"{np.sqrt((4 * 1.0 + 2 * 9.0) / 6):.2f}"  # 1.91; the shots' RMS of RMS would be 2.24
    bound_summary([full, rolling])
    intervals([full, rolling], n_boot=10)
    out = capsys.readouterr().out
    assert "all, with the fit's own measurements" in out and f"2 shots): {pooled}" in out, out
    assert "all: 2 ok; coverage" in out and f"RMS / bound {pooled}" in out, out
