"""The paper's answer against the maximum-likelihood fit's sliding time
(recover.estimate.sliding_times_agree, fit.decide.sliding_times_differ): H.264's drift can put the
segmentation's end of sliding early on a slide into the rest (case 2), and
the line method's answer then lies many of its stated errors off; the fit,
on the same frames, measures the sliding time right (docs/measurements.md,
paper32)."""

from __future__ import annotations

import numpy as np
import pytest

import cuespin.fit.decide as decide_module
from cuespin.physics.motion import BallParams
from cuespin.recover.estimate import estimate
from cuespin.recover.mle import model_track
from cuespin.recover.paper import sliding_time, sliding_time_stderr
from cuespin.recover.simulate import case2_tracks, shared_errors


def test_sliding_time_stderr_is_the_spread_of_eq10():
    # The delta method against draws of (v0, w0) from their covariance: at a
    # slip 50 times its error the sliding time is linear enough for the
    # spread of 20000 draws (its own standard error 0.5%) to be within 2%.
    p = BallParams()
    v0, w0 = np.array([0.8, -0.3]), np.array([12.0, 25.0])
    A = np.array([[2e-3, 1e-3, 0, 0], [0, 3e-3, 0, 0], [0.1, 0, 0.4, 0.2], [0, -0.1, 0, 0.5]])
    cov = A @ A.T
    draws = np.random.default_rng(3).multivariate_normal(np.r_[v0, w0], cov, 20000)
    taus = [sliding_time(d[:2], d[2:], p) for d in draws]
    assert sliding_time_stderr(v0, w0, cov, p) == pytest.approx(np.std(taus), rel=0.02)
    assert np.isnan(sliding_time_stderr(v0, w0, None, p))


def _case2_shared(n: int, seed: int = 7):
    """case2_tracks at 1e-4 and 3e-4 m, the whole error 4 sigma^2 correlated
    in time as H.264's (recover.simulate.shared_errors), as the calibration
    drew them (docs/measurements.md, paper32: /tmp/paper32/sim.py)."""
    rng = np.random.default_rng(seed + 1000)
    for tr in case2_tracks(n, seed=seed, sigma_grid=(1e-4, 3e-4), blur=False):
        m = len(tr.t)
        xy = model_track(tr.shot, tr.params, tr.t, tr.exposure_s) + 2.0 * tr.sigma * shared_errors(m, tr.fps, rng)
        yield tr, xy


def _estimate(tr, xy):
    m = len(tr.t)
    return estimate(tr.t, xy, np.full(m, tr.sigma), tr.params, tr.exposure_s, lossless=False, inter_frame=True)


def _z(p, tr):
    return np.r_[(p.v0 - tr.shot.v0) / p.stderr["v0"], (p.w0 - tr.shot.w0) / p.stderr["w0"]]


def test_an_early_end_of_sliding_gives_way_to_the_slide_into_the_rest(monkeypatch):
    # Track 15 of these (480 fps, 3e-4 m): the line's answer from the
    # breakpoint 18.1 stated errors off (RMS) and ok without the rule, its
    # sliding time 5.6 errors from the fit's; the segmentation's other
    # reading, a slide into the rest (case 2), answers within 1.6 stated
    # errors and agrees with the fit: that is the answer (measured: all 11
    # answers the rule refused on 250 such tracks, 120-480 fps, shared and
    # independent errors, answered so within 1.6).  The 14 answers within 3
    # of their errors in every component among the first 15: untouched
    # (measured |z| <= 3.2 over 216 such answers).
    from cuespin.recover.paper import ran_into_rest
    tracks = list(_case2_shared(16))
    tr, xy = tracks[15]
    est = _estimate(tr, xy)
    assert est.paper.status == "ok" and np.all(np.abs(_z(est.paper, tr)) < 3) and ran_into_rest(est.seg)
    # One decision: the breakpoint's sliding time differs, so the slide into
    # the rest is the segmentation chosen (and kept for a refit), its answer
    # held to the fit as any other.
    assert est.decisions["breakpoint_differs"] and est.decided.segments == "unended"
    assert est.decided.sliding_times_agree is True
    with monkeypatch.context() as m:
        m.setattr(decide_module, "PAPER_FIT_TAU_Z", float("inf"))
        off = _estimate(tr, xy).paper
        assert off.status == "ok" and np.sqrt(np.mean(_z(off, tr) ** 2)) > 5
        right = []
        for tr, xy in tracks[:15]:
            p = _estimate(tr, xy).paper
            if p.status == "ok" and np.all(np.abs(_z(p, tr)) < 3):
                right.append((tr, xy, p))
    assert len(right) >= 8
    for tr, xy, p in right:
        got = _estimate(tr, xy).paper
        assert got.status == "ok" and np.allclose(got.v0, p.v0) and np.allclose(got.w0, p.w0)


def _touched_runs(n: int, seed: int = 5):
    """sliding_tracks (random, case3; 120 and 240 fps; 1e-4 m) with H.264's
    shared error and the frames from the strike to 50 ms past the end of
    sliding flagged as the cue's touched run (no bias: the cue left the
    centres alone), as /tmp/paper32/touchsim.py drew them (paper32)."""
    from cuespin.physics.motion import phases
    from cuespin.recover.simulate import sliding_tracks
    rng = np.random.default_rng(seed + 1000)
    for tr in sliding_tracks(n, seed=seed, presets=("random", "case3"), fps_grid=(120.0, 240.0),
                             sigma_grid=(1e-4,), blur=False):
        m = len(tr.t)
        xy = model_track(tr.shot, tr.params, tr.t, tr.exposure_s) + 2.0 * tr.sigma * shared_errors(m, tr.fps, rng)
        touched = (tr.t > tr.shot.t0) & (tr.t < phases(tr.shot, tr.params).t1 + 0.05)
        yield tr, xy, touched


def test_where_the_trusted_frames_cannot_know_the_paper_is_degenerate():
    from cuespin.recover.estimate import trusted_frames_refuse
    # The fit on the frames left after the cue's touched run cannot determine
    # v0 (the run covers the whole slide): the paper's answer, whose
    # segmentation took the run's frames, is degenerate, right (track 4,
    # 1.2 stated errors) or wrong (track 6).  paper32 answered these from a
    # second recovery on every frame (right on realistic H.264 32/22 and
    # 71/0, in sample); on 80 held-out realistic shots (seeds 34, 36) that
    # case never arose, so the rule is not kept (docs/measurements.md,
    # fixpaper).
    tracks = list(_touched_runs(7))
    for k in (4, 6):
        tr, xy, touched = tracks[k]
        est = estimate(tr.t, xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s, lossless=False,
                       inter_frame=True, touched=touched)
        # Which verdict refuses depends on where the ill-conditioned fit ends
        # in its flat valley, which moved between machines (numpy/BLAS
        # builds; docs/measurements.md, determ): v0 not determined, or the
        # slide seen in fewer than MIN_SLIDING_FRAMES trusted frames.
        assert est.mle.status == "degenerate" and trusted_frames_refuse(est.mle), est.mle.verdicts
        assert est.paper.status == "degenerate" and est.paper.reason == est.mle.reason, est.paper.reason


def test_paper_verdicts_refuse_what_the_trusted_frames_cannot_know_and_a_disagreeing_slide():
    from cuespin.recover.estimate import paper_verdicts
    from cuespin.recover.mle import MLEResult
    from cuespin.recover.paper import PaperResult
    p = BallParams()
    paper = PaperResult("ok", "", "parabola", v0=np.array([1.0, 0.0]), w0=np.array([0.0, 10.0]))
    blind = MLEResult("degenerate", "v0 not determined", verdicts={"v0_determined": False})
    # refused whatever a sliding time said (a refit's kept agreement too)
    for agree in (True, False, None):
        assert paper_verdicts(paper, blind, False, p, agree).status == "degenerate"
    fit = MLEResult("ok", "", verdicts={"v0_determined": True, "strike_seen": True})
    assert paper_verdicts(paper, fit, False, p, False).status == "failed"
    assert paper_verdicts(paper, fit, False, p, True) is paper
    assert paper_verdicts(paper, fit, False, p, None) is paper  # nothing to compare (no covariance)


@pytest.mark.slow
def test_right_answers_are_rarely_refused_by_the_fits_sliding_time(monkeypatch):
    # The rule's false refusals: the paper's right answers (every component
    # within 3 stated errors) on 250 case-2 tracks with H.264's shared error
    # (seed 7) and 200 with independent errors (seed 8), where the paper's
    # case 2 fails most: at most fit.decide.SLIDING_TIMES_LEVEL plus two binomial
    # standard errors (measured 1 of 399; 755 s wall at load 15, 2 cores).
    from cuespin.fit.decide import PAPER_FIT_TAU_Z
    from cuespin.recover.estimate import sliding_time_z
    monkeypatch.setattr(decide_module, "PAPER_FIT_TAU_Z", float("inf"))
    right = refused = 0

    def count(tr, xy, lossless):
        nonlocal right, refused
        m = len(tr.t)
        est = estimate(tr.t, xy, np.full(m, tr.sigma), tr.params, tr.exposure_s, lossless=lossless,
                       inter_frame=not lossless)
        p = est.paper
        if p.status != "ok" or not p.stderr or not np.all(np.abs(_z(p, tr)) < 3):
            return
        z = sliding_time_z(p, est.mle, tr.params)
        right += 1
        refused += bool(np.isfinite(z) and abs(z) > PAPER_FIT_TAU_Z)

    for tr, xy in _case2_shared(250):
        count(tr, xy, False)
    for tr in case2_tracks(200, seed=8, sigma_grid=(1e-4, 3e-4), blur=False):
        count(tr, tr.xy, True)
    rate = decide_module.SLIDING_TIMES_LEVEL
    assert right >= 390
    assert refused <= right * rate + 2 * np.sqrt(right * rate * (1 - rate)), (refused, right)


def test_paper_refused_where_the_fit_does_not_see_sliding_end():
    # Realistic H.264 37/31 (held37): the true slide ends 0.07 s after the last
    # fitted frame; the fit said so (slide_ends False: a slide through every
    # frame fits about as well) and was degenerate, while the paper's
    # segmentation put x1 inside the track and answered ok, w0 9.9 stated
    # errors off, given as best.  Whatever the paper's segments, it follows
    # the fit's verdict with the fit's reason.
    from cuespin.recover.estimate import paper_verdicts
    from cuespin.recover.mle import MLEResult
    from cuespin.recover.paper import PaperResult
    p = BallParams()
    paper = PaperResult("ok", "", "parabola", v0=np.array([1.0, 0.0]), w0=np.array([0.0, 10.0]))
    unended = MLEResult("degenerate", "the track ends (t = 1.075 s) before sliding does",
                        verdicts={"v0_determined": True, "slide_ends": False, "strike_seen": True})
    for rolling in (False, True):
        for agree in (True, None):
            got = paper_verdicts(paper, unended, rolling, p, agree)
            assert got.status == "degenerate" and got.reason == unended.reason
    ended = MLEResult("ok", "", verdicts={"v0_determined": True, "slide_ends": True, "strike_seen": True})
    assert paper_verdicts(paper, ended, False, p, True) is paper


def test_paper_ok_always_states_its_errors():
    # Realistic H.264 37/1 and 38/22 (held37): an input moved by 1e-3 of its
    # error one way gave no root, and with_stderr returned the answer ok with
    # no errors (29% and 12% off in v0).  sliding_tracks(200, 11)'s track 55
    # (480 fps, parabola) is that case on a plain simulated track.  pap37
    # gave it one-sided errors; but its root vanishes both ways at 0.01 of
    # an input's error (the review of pap37, onesided.py): the answer exists
    # only on a sliver of its inputs' errors, and is `degenerate` with that
    # reason (recover.paper.ROOT_SPAN_SIGMAS), never ok without errors.
    from itertools import islice

    from cuespin.recover.simulate import sliding_tracks
    tr = next(islice(sliding_tracks(56, 11), 55, None))
    est = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s)
    p = est.paper
    assert p.status == "degenerate" and "sliver" in p.reason and p.v0 is None and not p.stderr, p


@pytest.mark.slow  # 60 simulated tracks: about 15-50 s
def test_paper_errors_cover_rolling_from_the_strike():
    # Review of pap37 (case4_rest.py 60 5, the same tracks): case-4 shots
    # slowed to rest in view.  pap37 moved x1 apart from x0 (a shorter slide
    # has no root) and took one-sided differences: coverage 75.0% of 192
    # components, RMS z 3.36, max |z| 27.  Now the answer is propagated from
    # (x0, x2) with x1 tied to x0, and x0 carries the strike time's error
    # (fit.segment._geometry_cov): measured 96.9%, RMS z 1.08.  Asked: each
    # answer's four components within 1.96 stated errors 95% of the time,
    # within two binomial standard errors counted over the answers (v0 along
    # the path and w0 across it share one error: z equal).
    from cuespin.recover.simulate import rolls_to_rest_tracks

    Z = []
    for tr in rolls_to_rest_tracks(60, 5, presets=("case4",)):
        p = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s).paper
        if p is not None and p.status == "ok":
            Z.append((np.r_[p.v0, p.w0] - np.r_[tr.shot.v0, tr.shot.w0]) / np.r_[p.stderr["v0"], p.stderr["w0"]])
    Z = np.abs(np.array(Z))
    assert len(Z) >= 40, len(Z)
    margin = 2 * np.sqrt(0.95 * 0.05 / len(Z))
    assert abs(np.mean(Z < 1.96) - 0.95) <= margin, (np.mean(Z < 1.96), len(Z))
