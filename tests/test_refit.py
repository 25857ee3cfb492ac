"""A refit through another camera keeps the first recovery's decisions
(recover.estimate.Decided): the segmentation's kind and the paper's root,
with standard errors for a root chosen that way."""

from dataclasses import replace

import numpy as np

import cuespin.recover.paper as paper_mod
from cuespin.data_gen.sampler import sample_shot
from cuespin.fit.decide import t1_in_view
from cuespin.physics import phases
from cuespin.recover.estimate import estimate
from cuespin.recover.simulate import simulate_track


def _case5(seed=0):
    rng = np.random.default_rng(seed)
    shot, p = sample_shot(rng, "case5")
    return simulate_track(shot, p, 120.0, 2e-5, rng, t_end=phases(shot, p).t2 + 0.3)


def test_root_kept_from_the_first_answer_has_standard_errors(monkeypatch):
    # A case-5 straight shot whose line method has two roots once the
    # sliding time no longer breaks the tie (the tolerance opened): a refit
    # keeping the first answer's root answers ok with that root and states
    # its errors (before: ok with no standard errors).
    tr = _case5()
    sig = np.full(len(tr.t), tr.sigma)
    monkeypatch.setattr(paper_mod, "TIE_T1_FRAMES", 1e6)
    first = estimate(tr.t, tr.xy, sig, tr.params, 0.0)
    assert first.paper.status == "ambiguous"
    root = first.paper.solutions[1]
    keep = replace(first.decided, paper=(root["v0"], root["w0"]))
    again = estimate(tr.t, tr.xy, sig, tr.params, 0.0, keep=keep)
    assert again.paper.status == "ok"
    assert np.allclose(again.paper.v0, root["v0"], rtol=1e-3)
    assert set(again.paper.stderr) == {"v0", "w0"}
    assert np.all(np.isfinite(again.paper.stderr["v0"])) and np.all(again.paper.stderr["v0"] > 0)


def test_refit_keeps_a_breakpoint_in_view():
    # A track cut while the ball still slides: its best segmentation slides to
    # the end.  A refit told to keep a breakpoint in view (a first camera
    # that saw one) searches from it and keeps one in view; told to keep
    # "sliding to the end" it keeps that (before: the default segmentation,
    # whatever its kind).
    rng = np.random.default_rng(4)
    shot, p = sample_shot(rng, "masse")
    ph = phases(shot, p)
    tr = simulate_track(shot, p, 240.0, 1e-4, rng, t_end=shot.t0 + 0.7 * (ph.t1 - shot.t0))
    sig = np.full(len(tr.t), tr.sigma)
    first = estimate(tr.t, tr.xy, sig, tr.params, 0.0, run_paper=True)
    assert first.decided.breaks is not None and not np.isfinite(first.decided.breaks[1])
    t_mid = shot.t0 + 0.5 * (ph.t1 - shot.t0)
    kept = replace(first.decided, segments="sliding", breaks=(first.decided.breaks[0], t_mid))
    again = estimate(tr.t, tr.xy, sig, tr.params, 0.0, keep=kept)
    assert t1_in_view(again.seg.t1, tr.t)
    same = estimate(tr.t, tr.xy, sig, tr.params, 0.0, keep=first.decided)
    assert not np.isfinite(same.seg.t1)


def test_refit_keeps_the_first_fits_verdicts(monkeypatch):
    # The status rules (MIN_SLIDING_FRAMES, MAX_REL_STDERR_V0), the HAC
    # question and the paper's case-2 question are answered once, on the
    # first camera; a refit through a perturbed camera keeps the answers.
    # Made to answer the other way here (thresholds that no track passes,
    # every residual autocorrelated, every stop apart), a refit that asked
    # again would flip to degenerate/HAC/failed; it must not.
    import cuespin.recover.mle as mle_mod
    from cuespin.fit.decide import Decision

    rng = np.random.default_rng(2)
    shot, p = sample_shot(rng, "case2")
    tr = simulate_track(shot, p, 120.0, 2e-5, rng, t_end=phases(shot, p).t2 + 0.3)
    sig = np.full(len(tr.t), tr.sigma)
    first = estimate(tr.t, tr.xy, sig, tr.params, 0.0)
    assert first.mle.status == "ok" and first.mle.model == "full"
    assert first.decided.verdicts == {"v0_determined": True, "sliding_frames": True, "strike_seen": True,
                                      "slide_ends": True}
    assert first.decided.hac is False and first.mle.hac is False
    assert first.paper.stop_apart is False and first.decided.stop_apart is False
    monkeypatch.setattr(mle_mod, "MIN_SLIDING_FRAMES", 10**6)
    monkeypatch.setattr(mle_mod, "MAX_REL_STDERR_V0", 0.0)
    monkeypatch.setattr(mle_mod, "strike_in_view", lambda t, t0, touched=None, xy=None, cov=None: False)
    monkeypatch.setattr(mle_mod, "slide_through_excluded", lambda d: Decision(False, d, 0.0))
    monkeypatch.setattr(mle_mod, "autocorrelated", lambda rho, z: Decision(True, z, 0.0))
    monkeypatch.setattr(paper_mod, "stop_apart", lambda d2: Decision(True, d2, 0.0))
    again = estimate(tr.t, tr.xy, sig, tr.params, 0.0, keep=first.decided)
    assert again.mle.status == "ok" and again.mle.model == "full" and again.mle.hac is False
    assert again.paper.status == first.paper.status == "ok"
    # The same rules unkept: the first fit itself answers degenerate.
    fresh = estimate(tr.t, tr.xy, sig, tr.params, 0.0)
    assert fresh.mle.status == "degenerate" and fresh.mle.hac is False


def test_no_hac_on_top_of_the_ar1_model(monkeypatch):
    # The AR(1) question is put once (recover.estimate, on the first fit's
    # residuals, where fit.decide calibrated it); slip_lr and the covariance
    # do not ask it again of the prewhitened residuals.
    import cuespin.recover.mle as mle_mod
    from cuespin.fit.decide import Decision

    calls = []

    def never(rho, z):
        calls.append(rho)
        return Decision(True, z, 0.0)

    monkeypatch.setattr(mle_mod, "autocorrelated", never)
    tr = _case5()
    sig = np.full(len(tr.t), tr.sigma)
    est = estimate(tr.t, tr.xy, sig, tr.params, 0.0)
    assert "autocorrelated" in est.decisions and not calls
    assert est.mle.hac is False and est.decided.hac is False


def test_refit_states_the_first_recoverys_paper_errors():
    # A refit keeping the first recovery's decisions on the SAME track and
    # camera states the same paper errors: both take the MLE's error model
    # (AR(1), scale; recover.estimate.mle_noise).  Before, the refit dropped
    # it and stated 0.38-1.0 of the first's errors on AR(1) tracks.
    from cuespin.recover.simulate import sliding_tracks

    tr = list(sliding_tracks(6, 1, rho=0.8))[5]
    sig = np.full(len(tr.t), tr.sigma)
    first = estimate(tr.t, tr.xy, sig, tr.params, tr.exposure_s, ar1_floor=0.5)
    assert first.decided.ar1 > 0.5 and first.paper.status == "ok"
    again = estimate(tr.t, tr.xy, sig, tr.params, tr.exposure_s, ar1_floor=0.5, keep=first.decided)
    assert again.paper.status == "ok"
    for key in ("v0", "w0"):
        assert np.allclose(again.paper.stderr[key], first.paper.stderr[key], rtol=1e-6)
