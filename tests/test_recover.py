"""recover/: the paper's closed forms, the maximum-likelihood fit, and the
whole pipeline end to end (generate, render, track, fit, recover)."""

import json
import subprocess
import sys

import numpy as np
import pytest

from cuespin.data_gen.sampler import make_scene, sample_shot
from cuespin.physics import BallParams, Shot, phases, positions, rolling_deceleration, sliding_parabola
from cuespin.physics.straight import straight_frame
from cuespin.pipeline.io import write_scene
from cuespin.recover.estimate import estimate
from cuespin.recover.paper import recover_line, recover_parabola, sliding_time
from cuespin.fit.segment import segment_track
from cuespin.render import render_video

EXACT = 1e-9  # the issue: closed forms on exact tracks return the truth to 1e-9
# The MLE's errors in units of its own standard errors: measured max 3.7 over
# the end-to-end scenes below (MJPG, sigma 3), ~N(0,1) on synthetic tracks.
MLE_Z_MAX = 5.0
# The paper's method end to end, measured over the scenes below: |dv0|/|v0| up
# to 1.2e-3 and R|dw0|/|v0| up to 5.5e-3; tolerances are 4x those.
PAPER_V0_REL = 5e-3
PAPER_RW_REL = 2.5e-2
# Case 2 sits on a kink of the likelihood (R w0 = -5/2 v0: any neighbour
# either rolls on or reverses), where Jacobian standard errors are
# optimistic: w0 measured 5.4 of them off, R|dw0|/|v0| = 9.3e-3.  Held to 3x
# the measured error instead.
MLE_CASE2_RW_REL = 3e-2


# -- closed forms on exact inputs -------------------------------------------------

@pytest.mark.parametrize("preset,seed", [("masse", s) for s in range(4)] + [("random", s) for s in range(6)])
def test_paper_parabola_exact(preset, seed):
    shot, p = sample_shot(100 + seed, preset)
    ph = phases(shot, p)
    par = sliding_parabola(shot.x0, shot.v0, shot.w0, p)
    r = recover_parabola(par, ph.x0, ph.x1, p, EXACT)
    assert r.status == "ok", r.reason
    np.testing.assert_allclose(r.v0, shot.v0, atol=EXACT)
    np.testing.assert_allclose(r.w0, shot.w0, atol=EXACT / p.R)  # rad/s: 1e-9 m/s of R w0


@pytest.mark.parametrize("case", range(1, 6))
def test_paper_line_exact(case):
    for seed in range(3):
        shot, p = sample_shot(200 + 10 * case + seed, f"case{case}")
        ph = phases(shot, p)
        heading = np.array(shot.v0) / np.hypot(*shot.v0)
        r = recover_line(ph.x0, ph.x1, ph.x2, p, EXACT, heading, ph.t1 - shot.t0, EXACT)
        sols = [{"v0": r.v0, "w0": r.w0}] if r.status == "ok" else r.solutions
        assert r.status in ("ok", "ambiguous"), r.reason
        if r.status == "ambiguous":  # only where the sliding time cannot tell the roots apart
            taus = [sliding_time(s["v0"], s["w0"], p) for s in sols]
            assert max(taus) - min(taus) < EXACT, taus
        # Without the sliding time, the tie the issue found (case 5 and some of case 3).
        untied = recover_line(ph.x0, ph.x1, ph.x2, p, EXACT, heading)
        assert untied.status in ("ok", "ambiguous")
        errs = [max(np.abs(s["v0"] - shot.v0).max(), p.R * np.abs(s["w0"] - shot.w0).max()) for s in sols]
        assert min(errs) < EXACT  # the truth is a solution
        if r.status == "ambiguous":  # and every listed solution reproduces x1 and x2
            for s in sols:
                alt = phases(Shot(shot.x0, s["v0"], s["w0"], shot.t0), p)
                np.testing.assert_allclose(alt.x1, ph.x1, atol=1e-9)
                np.testing.assert_allclose(alt.x2, ph.x2, atol=1e-9)


def test_paper_line_without_rest_point_is_degenerate():
    from cuespin.recover.paper import paper_from_segments
    shot, p = sample_shot(5, "case3")
    ph = phases(shot, p)
    t = np.arange(0, shot.t0 + 0.5 * (ph.t2 - shot.t0), 1 / 240)
    xy = positions(shot, p, t) + 2e-5 * np.random.default_rng(0).standard_normal((len(t), 2))
    seg = segment_track(t, xy, rolling_deceleration(p.mu_r, p.g), 2e-5)
    r = paper_from_segments(seg, t, xy, p, 2e-5, 1 / 240)
    assert r.status == "degenerate" and "rest point" in r.reason


@pytest.mark.parametrize("seed", [1, 2])
def test_paper_refuses_sliding_seen_in_one_or_two_frames(seed):
    # benchmarks/short_slide.py's shot (case 4 given a slip of 1.5 frames at
    # 60 fps), with its rest in view: the segmentation's sliding arc holds 1-2
    # frames, so x1 and t1 rest on where sliding ends between frames (seed
    # 21's realistic MJPG shot 13: the line's answer 29 stated errors off).
    from cuespin.physics.motion import z_cross
    from cuespin.recover.estimate import estimate
    from cuespin.recover.paper import PAPER_MIN_SLIDING_FRAMES
    from cuespin.recover.simulate import simulate_track
    fps, sigma = 60.0, 1e-4
    shot, p = sample_shot(seed, "case4")
    u0 = 3.5 * p.mu_s * p.g * (1.5 / fps) * np.array([0.6, 0.8])  # eq. 10
    v0 = np.asarray(shot.v0, float)
    s = Shot(x0=shot.x0, v0=v0, w0=z_cross(v0 - u0) / p.R, t0=shot.t0)
    tr = simulate_track(s, p, fps, sigma, seed, t_end=phases(s, p).t2 + 0.3)
    r = estimate(tr.t, tr.xy, np.full(len(tr.t), sigma), p).paper
    assert r.status == "degenerate", (r.status, r.reason)
    seen = int(r.reason.split("sliding seen in ")[1].split(" ")[0])
    assert 1 <= seen < PAPER_MIN_SLIDING_FRAMES


def short_slide_shot(seed, k):
    """benchmarks/short_slide.py's k-th shot (1-based) of ``seed``, run on
    until the rest is in view: case 4 given a slip of 0.2-8 frames (eq. 10)
    at 60/120/240 fps and 2e-5/1e-4/6e-4 m noise in turn.  Returns the track,
    its BallParams, sigma (m), exposure (s) and the true v0 (m/s)."""
    from cuespin.physics.motion import z_cross
    from cuespin.recover.simulate import simulate_track
    rng = np.random.default_rng(seed)
    for i in range(k):  # the generator's draws up to its k-th shot
        fps = (60.0, 120.0, 240.0)[i % 3]
        sigma = (2e-5, 1e-4, 6e-4)[(i // 3) % 3]
        shot, p = sample_shot(rng, "case4")
        tau1 = float(rng.uniform(0.2, 8.0)) / fps
        ang = rng.uniform(0, 2 * np.pi)
        u0 = 3.5 * p.mu_s * p.g * tau1 * np.array([np.cos(ang), np.sin(ang)])  # eq. 10
        v0 = np.asarray(shot.v0, float)
        s = Shot(x0=shot.x0, v0=v0, w0=z_cross(v0 - u0) / p.R, t0=shot.t0)
        exposure = float(rng.uniform(0.3, 1.0) / fps) if rng.random() < 0.5 else 0.0
        tr = simulate_track(s, p, fps, sigma, rng, exposure, t_end=phases(s, p).t2 + 0.3)
    return tr, p, sigma, exposure, v0


def test_paper_refuses_the_one_frame_arc_it_once_answered_196_percent_off(monkeypatch):
    # benchmarks/short_slide.py's generator with the rest in view (seed 5,
    # its 148th shot: case 4 given a slip of 0.70 frames at 60 fps, 1e-4 m):
    # the segmentation's arc holds 1 frame; with neither refusal the line
    # answered ok, v0 196% off (rec8; review 10c: the test above's shots
    # were already failed before the rule).  Each refusal catches it alone.
    import cuespin.recover.paper as paper
    from cuespin.recover.estimate import estimate
    tr, p, sigma, exposure, v0 = short_slide_shot(5, 148)

    def paper_answer():
        return estimate(tr.t, tr.xy, np.full(len(tr.t), sigma), p, exposure).paper

    # The slip ratio (28.2) passes its threshold on the one slid frame alone
    # (8.8 without it): rolling, and the paper's rolling answer refused
    # (docs/measurements.md, slip2).
    r = paper_answer()
    assert r.status == "degenerate" and "one measurement alone" in r.reason, r.reason
    # The refusals of the slide's answer, reached with the slip decided on the
    # ratio alone (before slip2).
    import cuespin.recover.estimate as estimate_module
    monkeypatch.setattr(estimate_module, "slip_lr_without_largest", lambda full, roll, lr: lr)
    assert paper_answer().status == "degenerate"
    monkeypatch.setattr(paper, "PAPER_MIN_SLIDING_FRAMES", 1)
    assert paper_answer().status == "failed"  # the sliding-time check alone
    monkeypatch.setattr(paper, "SLIDING_TIME_TOLERANCES", np.inf)
    # The fit's verdict on its trusted frames (the slide seen in 1 of them,
    # under MIN_SLIDING_FRAMES) refuses it a third way since the paper
    # follows ``sliding_frames`` (recover.estimate.trusted_frames_refuse).
    r = paper_answer()
    assert r.status == "degenerate" and "seen in 1 frame" in r.reason, r.reason
    monkeypatch.setattr(estimate_module, "trusted_frames_refuse", lambda mle: False)
    r = paper_answer()  # none: the confident wrong answer they exist for
    assert r.status == "ok" and np.linalg.norm(np.asarray(r.v0) - v0) > np.linalg.norm(v0)


def test_paper_refuses_an_answer_that_slides_longer_than_the_track(monkeypatch):
    # benchmarks/short_slide.py's generator with the rest in view (seed 5,
    # its 12th shot: case 4 given a slip of 2.15 frames at 240 fps, 2e-5 m):
    # the segmentation's arc holds 3 frames (0.010 s of sliding) and the
    # line's root slides 3.29 s (eq. 10), its v0 200% off, once answered ok
    # (docs/measurements.md, arc9).  Since slip2 its slip ratio (31.2) passes
    # on one frame alone (4.8 without it) and the paper's rolling answer is
    # refused; the slide's answer is reached with the ratio alone.
    import cuespin.recover.estimate as estimate_module
    from cuespin.recover.estimate import estimate
    tr, p, sigma, exposure, _ = short_slide_shot(5, 12)
    assert estimate(tr.t, tr.xy, np.full(len(tr.t), sigma), p, exposure).paper.status == "degenerate"
    monkeypatch.setattr(estimate_module, "slip_lr_without_largest", lambda full, roll, lr: lr)
    r = estimate(tr.t, tr.xy, np.full(len(tr.t), sigma), p, exposure).paper
    assert r.status == "failed", (r.status, r.reason)
    assert "eq. 26" in r.reason and r.v0 is None


# -- maximum likelihood on synthetic tracks -----------------------------------------

def synthetic(shot, p, fps=240.0, sigma=2e-5, seed=0, t_cut=None):
    ph = phases(shot, p)
    t = np.arange(0.0, min(ph.t2 + 0.3, 5.0) if t_cut is None else t_cut, 1 / fps)
    xy = positions(shot, p, t, ph)
    return t, xy + sigma * np.random.default_rng(seed).standard_normal(xy.shape)


def mle_of(t, xy, p, sigma=2e-5, **kw):
    """The maximum-likelihood answer by the one path (recover.estimate)."""
    return estimate(t, xy, np.full(len(t), sigma), p, run_paper=False, **kw).mle


@pytest.mark.parametrize("preset,seed", [("random", 1), ("random", 2), ("case1", 3), ("case3", 4),
                                         ("case5", 5), ("masse", 7)])
def test_mle_within_its_standard_errors(preset, seed):
    shot, p = sample_shot(seed, preset)
    ph = phases(shot, p)
    t, xy = synthetic(shot, p, seed=seed, t_cut=min(ph.t2, ph.t1 + 1.0) + 0.2)
    m = mle_of(t, xy, p)
    assert m.status == "ok", m.reason
    assert m.model == "full"
    for key, true in (("v0", shot.v0), ("w0", shot.w0), ("x0", shot.x0)):
        z = np.abs((getattr(m, key) - np.array(true)) / m.stderr[key])
        assert z.max() < MLE_Z_MAX, (key, z)
    assert abs(m.t0 - shot.t0) < MLE_Z_MAX * m.stderr["t0"]
    assert m.chi2 / m.dof == pytest.approx(1.0, abs=0.15)


def test_mle_rolling_from_the_strike():
    shot, p = sample_shot(9, "case4")
    t, xy = synthetic(shot, p, t_cut=shot.t0 + 1.5)
    m = mle_of(t, xy, p)
    assert m.status == "ok" and m.model == "rolling"
    z = np.abs((m.w0 - np.array(shot.w0)) / m.stderr["w0"])
    assert z.max() < MLE_Z_MAX


@pytest.mark.parametrize("rolling,ar1,seed", [(False, 0.0, 1), (True, 0.0, 2), (False, 0.6, 3), (True, 0.6, 4),
                                               (False, 0.0, 5), (True, 0.3, 6)])
def test_fit_jacobian_is_the_residuals_derivative(rolling, ar1, seed):
    # The fits' exact Jacobian (physics.motion.positions_jacobian through the
    # exposure's average, the measurements' whitening and the AR(1)
    # prewhitening) against central differences of the residuals, at random
    # parameters near a shot that slides, rolls and rests in view (both
    # rests one measurement each, the strike's frame masked).
    from cuespin.recover.mle import ar1_prewhiten, jacobian_map, model_track, model_track_jacobian
    from cuespin.recover.measurements import build_measurements
    from cuespin.physics.motion import z_cross
    rng = np.random.default_rng(seed)
    shot, p = sample_shot(seed, "case4" if rolling else "random")
    ph = phases(shot, p)
    t, xy = synthetic(shot, p, fps=120.0, seed=seed, t_cut=min(ph.t2 + 0.3, shot.t0 + 3.0))
    exposure = 1 / 240.0
    meas = build_measurements(t, xy, 2e-5, t0=shot.t0, t_rest=ph.t2, exposure_s=exposure, frame_dt=1 / 120.0,
                              shared_rest=True)
    q = np.r_[shot.x0, shot.t0, shot.v0] if rolling else np.r_[shot.x0, shot.t0, shot.v0, shot.w0]
    q = q + rng.normal(0.0, [1e-3, 1e-3, 2e-3, 2e-2, 2e-2, 1.0, 1.0][:len(q)])

    def shot_of(q):
        return Shot(q[0:2], q[3:5], z_cross(q[3:5]) / p.R if rolling else q[5:7], q[2])

    def resid(q):
        return ar1_prewhiten(meas, meas.whiten(model_track(shot_of(q), p, meas.t_used, exposure)), ar1).ravel()

    J = jacobian_map(meas, ar1)(model_track_jacobian(shot_of(q), p, meas.t_used, exposure, rolling))
    assert J.shape == (2 * meas.n, len(q))
    for i in range(len(q)):
        h = 1e-7 * max(1.0, abs(q[i]))
        dq = np.zeros_like(q)
        dq[i] = h
        num = (resid(q + dq) - resid(q - dq)) / (2 * h)
        assert np.max(np.abs(num - J[:, i])) < 1e-6 * np.max(np.abs(J[:, i])), i


@pytest.mark.parametrize("rolling,ar1,seed,exposure", [(False, 0.0, 1, 1 / 240.0), (True, 0.6, 4, 1 / 240.0),
                                                        (False, 0.3, 5, 0.0)])
def test_fast_paths_give_the_same_numbers(rolling, ar1, seed, exposure):
    # The fits' fast paths are exact rearrangements, not approximations: a
    # sorted track's phases as slices against the masks (physics.motion),
    # and the forward difference's shots in one pass against one at a time
    # (recover.mle.forward_jacobian), bit for bit; the answers of 83af15c
    # are kept to the last bit on recover_speed.py's shots this way.
    from cuespin.physics.motion import evaluate, positions, positions_jacobian, z_cross
    from cuespin.recover.measurements import build_measurements
    from cuespin.recover.mle import TrackModel, forward_jacobian, prewhitener, residuals_many
    shot, p = sample_shot(seed, "case4" if rolling else "random")
    ph = phases(shot, p)
    t, xy = synthetic(shot, p, fps=120.0, seed=seed, t_cut=min(ph.t2 + 0.3, shot.t0 + 3.0))
    tt = np.sort(np.r_[t, ph.t1, ph.t2, shot.t0])  # boundaries on a frame: the later phase's
    assert np.array_equal(positions(shot, p, tt), evaluate(shot, p, tt).x)
    for r in (False, True):
        assert np.array_equal(positions_jacobian(shot, p, tt, r, ordered=True),
                              positions_jacobian(shot, p, tt, r, ordered=False))
    meas = build_measurements(t, xy, 2e-5, t0=shot.t0, t_rest=ph.t2, exposure_s=exposure, frame_dt=1 / 120.0,
                              shared_rest=True)
    model, prewhiten = TrackModel(meas.t_used, exposure), prewhitener(meas, ar1)

    def shot_of(q):
        return Shot(q[0:2], q[3:5], z_cross(q[3:5]) / p.R if rolling else q[5:7], q[2])

    def resid(q):
        return prewhiten(meas.whiten(model(shot_of(q), p))).ravel()

    q = np.r_[shot.x0, shot.t0, shot.v0] if rolling else np.r_[shot.x0, shot.t0, shot.v0, shot.w0]
    loop = forward_jacobian(resid, q, resid(q))
    many = forward_jacobian(resid, q, resid(q), many=lambda Q: residuals_many(meas, model, prewhiten,
                                                                              [shot_of(r) for r in Q], p))
    assert np.array_equal(loop, many)


@pytest.mark.parametrize("rolling,seed,start_off", [(False, 3, 0.0), (True, 4, 0.0), (False, 11, 0.3)])
def test_lm_fit_is_least_squares(rolling, seed, start_off, monkeypatch):
    # recover.mle.lm_fit is least_squares' lm call without its wrapper: the
    # same fit to the last bit (x, cost, residuals, Jacobian, status,
    # message), from the truth and from a start 30% off in speed and spin
    # (seed 11: a masse shot cut while sliding, rank-deficient Jacobians
    # and their forward differences).
    from scipy.optimize import least_squares

    import cuespin.recover.mle as mle
    from cuespin.recover.measurements import build_measurements
    shot, p = sample_shot(seed, "case4" if rolling else ("masse" if start_off else "random"))
    ph = phases(shot, p)
    t_cut = shot.t0 + 0.5 * (ph.t1 - shot.t0) if start_off else min(ph.t2 + 0.3, shot.t0 + 3.0)
    t, xy = synthetic(shot, p, fps=120.0, seed=seed, t_cut=t_cut)
    meas = build_measurements(t, xy, 2e-5, t0=shot.t0, t_rest=ph.t2, exposure_s=0.004, frame_dt=1 / 120.0,
                              shared_rest=True)
    k = 1.0 + start_off
    start = (shot.x0, shot.t0, k * np.asarray(shot.v0), k * np.asarray(shot.w0))
    new = mle.fit_model(meas, p, start, 0.004, rolling)

    def lm_fit(resid, p0, jac, x_scale, ftol, xtol, gtol, max_nfev):
        return least_squares(resid, p0, jac=jac, x_scale=x_scale, method="lm", xtol=xtol, ftol=ftol, gtol=gtol,
                             max_nfev=max_nfev)
    monkeypatch.setattr(mle, "lm_fit", lm_fit)
    old = mle.fit_model(meas, p, start, 0.004, rolling)
    for name in ("x", "jac", "residuals"):
        assert np.array_equal(getattr(new, name), getattr(old, name)), name
    assert (new.chi2, new.converged, new.message) == (old.chi2, old.converged, old.message)


def test_lm_fit_falls_back_to_least_squares_with_minpacks_scaling(monkeypatch):
    # Where scipy's private lmder is not usable (decided at import), lm_fit
    # is least_squares' lm with x_scale "jac" (scipy 1.16's default, the
    # scaling the private call uses): the same point on a curved fit.
    import cuespin.fit.lm as lm

    t = np.linspace(0.0, 2.0, 40)
    y = 1.5 * np.exp(-0.7 * t) + 0.01 * np.sin(13 * t)

    def resid(p):
        return p[0] * np.exp(-p[1] * t) - y

    def jac(p):
        e = np.exp(-p[1] * t)
        return np.c_[e, -p[0] * t * e]

    direct = lm.lm_fit(resid, [1.0, 0.1], jac)
    assert lm._lmder_answers()

    class Moved:  # a scipy whose private lmder takes other arguments
        @staticmethod
        def _lmder(*args):
            raise TypeError("_lmder() takes 11 positional arguments")

    monkeypatch.setattr(lm, "_minpack", Moved)
    assert not lm._lmder_answers()  # the probe import runs refuses it
    monkeypatch.setattr(lm, "_minpack", None)
    fallback = lm.lm_fit(resid, [1.0, 0.1], jac)
    assert np.allclose(direct.x, fallback.x, rtol=1e-10, atol=0) and fallback.success


def test_deficient_by_form_is_deficient():
    # recover.mle._deficient_by_form skips making the exact Jacobian where
    # its form makes it rank deficient (sliding past the track's end; free
    # slip without slip): the Jacobian's own test must agree at every such
    # point (and the form must not claim a track that sees sliding end).
    import cuespin.recover.mle as mle
    from cuespin.physics.motion import z_cross
    from cuespin.recover.measurements import build_measurements
    seen = {True: 0, False: 0}
    for seed in range(6):
        shot, p = sample_shot(seed, "random")
        ph = phases(shot, p)
        for cut, ex in ((0.5, 0.004), (3.0, 0.0)):  # cut while sliding; the whole shot
            t, xy = synthetic(shot, p, fps=120.0, seed=seed, t_cut=shot.t0 + cut * (ph.t1 - shot.t0) + 0.05 * (cut > 1))
            meas = build_measurements(t, xy, 2e-5, t0=shot.t0, t_rest=ph.t2, exposure_s=ex, frame_dt=1 / 120.0,
                                      shared_rest=True)
            model, jmap = mle.TrackModel(meas.t_used, ex), mle.jacobian_map(meas)
            for k, rolling in ((1.0, False), (0.7, False), (1.0, True)):
                v0 = k * np.asarray(shot.v0)
                for w0 in (np.asarray(shot.w0), z_cross(v0) / p.R):  # the second: no slip
                    s = Shot(shot.x0, v0, z_cross(v0) / p.R if rolling else w0, shot.t0)
                    q = phases(s, p)
                    if mle._deficient_by_form(model, q, rolling):
                        seen[q.t1 > model.last] += 1
                        assert mle._rank_deficient(jmap(model.jacobian(s, p, rolling)))
    assert seen[True] > 0 and seen[False] > 0, seen


def test_mle_degenerate_when_track_ends_while_sliding():
    shot, p = sample_shot(11, "masse")
    ph = phases(shot, p)
    t, xy = synthetic(shot, p, t_cut=shot.t0 + 0.5 * (ph.t1 - shot.t0))
    m = mle_of(t, xy, p)
    assert m.status == "degenerate" and m.w0 is None and "w0" in m.reason
    assert np.all(np.abs(m.v0 - np.array(shot.v0)) < MLE_Z_MAX * m.stderr["v0"])


def test_mle_degenerate_when_the_strike_is_not_in_view():
    # The track starts mid-shot: the strike's place, time and speed trade
    # along the path, and v0 is not an answer.
    shot, p = sample_shot(9, "case4")
    ph = phases(shot, p)
    t, xy = synthetic(shot, p, t_cut=ph.t2 + 0.3)
    late = t > shot.t0 + 0.5 * (ph.t2 - shot.t0)
    m = mle_of(t[late], xy[late], p)
    assert m.status == "degenerate" and "does not determine v0" in m.reason, m.reason
    assert m.v0 is None and m.w0 is None
    # The whole track from the same shot answers.
    assert mle_of(t, xy, p).status == "ok"


def test_a_track_touched_in_every_frame_is_answered_not_raised():
    # Held-out H.264 seed 54 shot 5 (a kept track whose every found frame the
    # tracker flagged as touched, found only from just after the strike): the
    # cue's window then covered the whole track, the measurements were empty,
    # and recover.measurements.group_shares raised on reshaping nothing.
    # Failure is an answer: a status and a reason, no number.
    shot, p = sample_shot(9, "case4")
    ph = phases(shot, p)
    t, xy = synthetic(shot, p, t_cut=ph.t2 + 0.3)
    late = t > shot.t0 + 0.02
    m = mle_of(t[late], xy[late], p, touched=np.ones(late.sum(), bool))
    assert m.status in ("degenerate", "failed") and m.reason, m.reason
    assert m.v0 is None and m.w0 is None


def test_mle_fits_friction_on_request():
    shot, p = sample_shot(13, "random")
    ph = phases(shot, p)
    t, xy = synthetic(shot, p, t_cut=min(ph.t2 + 0.3, 6.0))
    wrong = BallParams(mu_s=p.mu_s * 1.3, mu_r=p.mu_r * 0.7)
    m = mle_of(t, xy, wrong, fit_friction=True)
    assert m.status == "ok", m.reason
    assert abs(m.mu_s - p.mu_s) < MLE_Z_MAX * m.stderr["mu_s"]
    assert abs(m.mu_r - p.mu_r) < MLE_Z_MAX * m.stderr["mu_r"]


def test_mle_fails_plainly_when_the_model_cannot_describe_the_track():
    # Two different shots spliced: no single shot fits, and the answer must
    # say so rather than report the best of a bad fit as "ok".
    a, p = sample_shot(3, "random")
    b, _ = sample_shot(4, "random")
    t, xa = synthetic(a, p, t_cut=2.0)
    _, xb = synthetic(b, p, t_cut=2.0)
    xy = np.where((t > a.t0 + 0.3)[:, None], xb - xb[np.searchsorted(t, a.t0 + 0.3)] +
                  xa[np.searchsorted(t, a.t0 + 0.3)], xa)
    m = mle_of(t, xy, p)
    assert m.status == "failed" and "does not describe" in m.reason
    assert m.v0 is None and m.w0 is None


def codec_track(sigma: float, seed: int):
    """The codec tests' shot (sample_shot 3, "random") seen to its rest +
    0.3 s (at most 5 s) with per-axis noise ``sigma`` (m): shot, params, t,
    xy and every frame found."""
    shot, p = sample_shot(3, "random")
    t, xy = synthetic(shot, p, sigma=sigma, seed=seed, t_cut=min(phases(shot, p).t2 + 0.3, 5.0))
    return shot, p, t, xy, np.ones(len(t), bool)


def test_codec_error_is_measured_and_weighted():
    # A lossy codec adds error the tracker does not state: here 3e-5 m on top
    # of a stated 2e-5 m.  Expected precision of the measured excess: ~2.5%
    # (variance of ~2000 residual components); measured over seeds 5-8:
    # -2.0%, +0.4%, -1.2%, +3.4%.  Asserted within 10% (~4 of that spread).
    from cuespin.recover.api import recover_track
    stated, extra = 2e-5, 3e-5
    shot, p, t, xy, ok = codec_track(np.hypot(stated, extra), 5)
    lossy = recover_track(t, xy, ok, np.full(len(t), stated), p, lossless=False)["methods"]["mle"]
    assert lossy["status"] == "ok", lossy["reason"]
    assert lossy["codec_noise_m"] == pytest.approx(extra, rel=0.1)
    z = np.abs((np.array(lossy["v0"]) - shot.v0) / np.array(lossy["stderr"]["v0"]))
    assert z.max() < MLE_Z_MAX
    lossless = recover_track(t, xy, ok, np.full(len(t), stated), p, lossless=True)["methods"]["mle"]
    assert lossless["codec_noise_m"] == 0.0


def test_codec_error_below_the_stated_one_is_measured_negative():
    # MJPG at low noise: the tracker states 1.2-1.4 times its real error.
    # Stated 3e-5 m, real 2e-5 m: the codec's share is -sqrt(5e-10) m,
    # measured within 10% (as above).
    from cuespin.recover.api import recover_track
    stated, real = 3e-5, 2e-5
    shot, p, t, xy, ok = codec_track(real, 6)
    mle = recover_track(t, xy, ok, np.full(len(t), stated), p, lossless=False)["methods"]["mle"]
    assert mle["status"] == "ok", mle["reason"]
    assert mle["codec_noise_m"] == pytest.approx(-np.sqrt(stated**2 - real**2), rel=0.1)
    z = np.abs((np.array(mle["v0"]) - shot.v0) / np.array(mle["stderr"]["v0"]))
    assert z.max() < MLE_Z_MAX


def test_a_codec_share_the_tracker_states_is_counted_once():
    # The tracker states MJPG's error on the chroma's blocks by multiplying
    # each frame's covariance by track.misfit.JPEG_CHROMA_VAR; the recovery
    # measures the codec's share beyond the stated from the residuals
    # (recover.measurements.codec_excess).  The share is solved so that the
    # weighted residuals match the degrees of freedom, so a factor already in
    # the stated errors is taken back, not added a second time: on frames
    # stating one error the total (stated + share) is the same to the
    # solver's tolerance, and so are the answer and its stated errors
    # (measured on the realistic MJPG set, seed 21: the share per shot moved
    # by -0.14 of the stated variance in median when the factor was put in;
    # docs/measurements.md, rec7).
    from cuespin.recover.api import recover_track
    from cuespin.track.misfit import JPEG_CHROMA_VAR
    stated, real = 2e-5, 3e-5
    shot, p, t, xy, ok = codec_track(real, 7)
    plain, factored = (recover_track(t, xy, ok, np.full(len(t), s), p, lossless=False)["methods"]["mle"]
                       for s in (stated, stated * np.sqrt(JPEG_CHROMA_VAR)))
    assert plain["status"] == factored["status"] == "ok", (plain["reason"], factored["reason"])
    share = [np.sign(m["codec_noise_m"]) * m["codec_noise_m"] ** 2 for m in (plain, factored)]
    assert share[0] - share[1] == pytest.approx((JPEG_CHROMA_VAR - 1) * stated**2, rel=1e-6)
    for k in ("v0", "w0"):
        assert np.asarray(factored[k]) == pytest.approx(np.asarray(plain[k]), rel=1e-6)
        assert np.asarray(factored["stderr"][k]) == pytest.approx(np.asarray(plain["stderr"][k]), rel=1e-6)


def test_a_wrong_friction_is_refused_not_hidden_in_the_codec_noise():
    # A real H.264 video recovered with mu_r 0.01 where the cloth's is 0.0146
    # answered ok with v0 2-3 times the truth: the codec term grew to 40-55
    # times the tracker's stated error and took up the misfit (auto15).  The
    # same here: a 60 fps lossy track whose codec adds twice the stated
    # error, recovered with mu_r / 1.46.  Correct answers' codec noise
    # measured at most 2.8 times the stated (MAX_CODEC_NOISE_RATIO 10,
    # docs/measurements.md "guard1"); this one needs hundreds.
    import dataclasses
    from cuespin.recover.api import recover_track
    from cuespin.recover.measurements import MAX_CODEC_NOISE_RATIO
    shot, p = sample_shot(4, "random")
    stated = 2e-5
    t, xy = synthetic(shot, p, fps=60.0, sigma=np.hypot(stated, 2 * stated), seed=5,
                      t_cut=min(phases(shot, p).t2 + 0.3, 5.0))
    ok = np.ones(len(t), bool)
    right = recover_track(t, xy, ok, np.full(len(t), stated), p, lossless=False)["methods"]["mle"]
    assert right["status"] == "ok", right["reason"]
    assert abs(right["codec_noise_m"]) < MAX_CODEC_NOISE_RATIO * stated
    wrong = recover_track(t, xy, ok, np.full(len(t), stated), dataclasses.replace(p, mu_r=p.mu_r / 1.46),
                          lossless=False)["methods"]
    for name in ("paper", "mle"):
        assert wrong[name]["status"] == "failed", (name, wrong[name])
        assert "does not explain the track" in wrong[name]["reason"], wrong[name]["reason"]


# The generator's six cue-tip constructions (seeds 0-5): only 0 and 3 are
# refused.  The others bend the fit's path under a radius (steps 0.73,
# 0.58, 0.50, 0.13 R) and are answered ok 63-174% off (cov13, measured again
# by stats12b on c8c871f); seed 5's clean track is degenerate as well.  A
# threshold near 0.5 R would meet the renders' correct answers (0.51 R), so
# they stay strict xfails: an XPASS says the rule now reaches them.
_STEP_NOT_CAUGHT = pytest.mark.xfail(strict=True, reason="the fit bends through the tip's frames under MAX_STEP_R "
                                     "and answers ok 63-174% off (docs/measurements.md cov13, stats12b)")


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=_STEP_NOT_CAUGHT), pytest.param(2, marks=_STEP_NOT_CAUGHT),
                                  3, pytest.param(4, marks=_STEP_NOT_CAUGHT), pytest.param(5, marks=_STEP_NOT_CAUGHT)])
def test_a_track_that_steps_is_refused(seed):
    # H.264 realistic seed 23 shot 36 (docs/measurements.md "cov13"): the
    # tracker took the cue's tip, 1.4-2.7 radii behind the ball, for it
    # before the strike and for 18 frames after, found nothing for 13 more,
    # then the ball; the fit bent its path through both (v0 163% off, chi2/dof
    # 1.36, codec noise 3.4x stated) and both methods answered ok.  The same
    # here: frames to 10 after the strike 1.5 R behind the ball, the next 14
    # not found.  Refused by the step (MAX_STEP_R, 1 radius; correct answers
    # measured at most 0.5); the clean track is answered.  Not every such
    # track is caught: seeds 1, 2, 4 and 5 bend the fit's path under a radius
    # and are answered 63-174% off (docs/measurements.md "cov13").
    from cuespin.recover.api import recover_track
    from cuespin.recover.measurements import MAX_STEP_R
    shot, p = sample_shot(seed, "random")
    # 0.5 mm stated (shot 36's: 0.23 px at 2.4 mm/px), so the codec guard
    # does not refuse first (it did at 0.02 mm: 46-68x).
    stated, fps = 5e-4, 240.0
    t, xy = synthetic(shot, p, fps=fps, sigma=np.hypot(stated, 2 * stated), seed=seed,
                      t_cut=min(phases(shot, p).t2 + 0.3, 3.0))
    ok = np.ones(len(t), bool)
    kw = {"lossless": False, "inter_frame": True}
    clean = recover_track(t, xy, ok, np.full(len(t), stated), p, **kw)["methods"]["mle"]
    assert clean["status"] == "ok", clean["reason"]
    tip = t < shot.t0 + 10 / fps
    xy[tip] -= 1.5 * p.R * np.asarray(shot.v0) / np.hypot(*shot.v0)
    ok &= ~((t >= shot.t0 + 10 / fps) & (t < shot.t0 + 24 / fps))
    stepped = recover_track(t, xy, ok, np.full(len(t), stated), p, **kw)["methods"]
    assert 1.5 > MAX_STEP_R
    # The paper's method may have failed on its own first (seed 3: the path
    # not straight); failed either way.
    for name in ("paper", "mle"):
        assert stepped[name]["status"] == "failed", (name, stepped[name])
    assert "the track steps" in stepped["mle"]["reason"], stepped["mle"]["reason"]


# The step rule's false refusals: at most this rate (stated), held when the
# one-sided 95% upper bound of the count on STEP_NULL_TRACKS tracks without
# a cue tip is under it (0 of 400: 0.75%).
MAX_STEP_FALSE_REFUSAL = 0.01
STEP_NULL_TRACKS = 400


@pytest.mark.slow
def test_the_step_rule_refuses_no_track_without_a_cue_tip():
    # Out of sample for MAX_STEP_R (set on 133 realistic answers and 278
    # generated ones of seeds 100-399, cov13): sample_shot seeds 1000-1399
    # ("random"), 60-480 fps, stated 2e-5-5e-4 m with a codec adding twice
    # it, inter-frame (H.264) and intra-frame (MJPG) alternately in runs of
    # 12.  Measured (stats12b): 0 of 400 refused by the step, 389 MLE ok, 11
    # degenerate; the largest step 0.11 R (the renders' correct answers
    # reach 0.51 R: the generator has no tracker's outliers).  54 s.
    from scipy.stats import beta

    from cuespin.recover.api import recover_track
    fps_grid, stated_grid = (60.0, 120.0, 240.0, 480.0), (2e-5, 1e-4, 5e-4)
    refused = []
    for i, seed in enumerate(range(1000, 1000 + STEP_NULL_TRACKS)):
        shot, p = sample_shot(seed, "random")
        fps, stated = fps_grid[i % 4], stated_grid[(i // 4) % 3]
        t, xy = synthetic(shot, p, fps=fps, sigma=np.hypot(stated, 2 * stated), seed=seed,
                          t_cut=min(phases(shot, p).t2 + 0.3, 3.0))
        out = recover_track(t, xy, np.ones(len(t), bool), np.full(len(t), stated), p, lossless=False,
                            inter_frame=bool((i // 12) % 2))["methods"]
        if any("the track steps" in m["reason"] for m in out.values()):
            refused.append(seed)
    upper = beta.ppf(0.95, len(refused) + 1, STEP_NULL_TRACKS - len(refused))
    assert upper < MAX_STEP_FALSE_REFUSAL, (refused, upper)


@pytest.mark.slow
def test_correct_answers_with_codec_noise_are_not_refused():
    # The false refusals of MAX_CODEC_NOISE_RATIO on correct answers: 40
    # generated shots (sample_shot seeds 0-39, "random"), 60 fps, a lossy
    # codec adding 3 times the stated error (above the largest measured on
    # the realistic renders, 2.8; docs/measurements.md "guard1"), recovered
    # with the right friction: none refused by the rule (the measured
    # excess is within ~3% of the truth, test_codec_error_is_measured_and_weighted),
    # nor by the step (MAX_STEP_R).
    from cuespin.recover.api import recover_track
    stated = 2e-5
    refused = []
    for seed in range(40):
        shot, p = sample_shot(seed, "random")
        t, xy = synthetic(shot, p, fps=60.0, sigma=np.hypot(stated, 3 * stated), seed=seed,
                          t_cut=min(phases(shot, p).t2 + 0.3, 5.0))
        out = recover_track(t, xy, np.ones(len(t), bool), np.full(len(t), stated), p, lossless=False)["methods"]
        refused += [(seed, k) for k, m in out.items()
                    if "does not explain the track" in m["reason"] or "the track steps" in m["reason"]]
    assert not refused


# -- end to end: video in, v0 and w0 out ----------------------------------------------

def e2e_scene(kind):
    """Shots that stay on the table and stop in view (slow cloth), 120 fps, MJPG, sigma 3."""
    params = BallParams(mu_s=0.2, mu_r=0.02)
    heading = np.array([np.cos(0.2), np.sin(0.2)])
    _, j = straight_frame(heading, np.zeros(2))
    k = {"case1": -3.2, "case2": -2.5, "case3": 0.0, "case4": 1.0, "case5": 2.0}
    if kind in k:
        speed = {"case4": 0.5, "case5": 0.5}.get(kind, 0.8)
        x0 = (1.2, 0.45) if kind in ("case1", "case2") else (0.6, 0.45)
        shot = Shot(x0, speed * heading, k[kind] * speed / params.R * j, t0=0.2)
    elif kind == "curved_right":
        shot = Shot((0.5, 0.35), (0.9, 0.25), (30.0, -40.0), t0=0.25)
    else:  # curved_left: the mirror image, spin sign flipped
        shot = Shot((0.6, 0.9), (0.9, -0.25), (-30.0, -40.0), t0=0.3)
    return make_scene(shot, params, fps=120.0, render={"noise_sigma": 3.0, "codec": "MJPG", "seed": 1})


def test_strike_frames_left_out_where_the_fit_puts_the_strike(tmp_path):
    # Shot 150 of the accuracy benchmark (seed 0): rolling from the strike
    # at 60 fps, exposure 0.7 frame.  The segmentation's t0 is 0.8 frame
    # early, so leaving out the strike's frames around it kept the frame
    # just after the strike (half still, half moving) and dropped the one
    # before: free slip passed the test (LR 20.8) on that frame alone and v0
    # came out 1.6% off, at 9 stated errors.
    from cuespin.data_gen.sampler import sample_scenes
    from cuespin.pipeline.run import run_recover
    scene = sample_scenes(151, 0)[150]
    scene.render["max_duration"] = 6.0
    video = tmp_path / "shot.avi"
    render_video(scene, video)
    mle = run_recover(video, scene, method="mle")["methods"]["mle"]
    assert mle["status"] == "ok" and mle["model"] == "rolling", (mle["model"], mle["slip_lr"])
    z = np.abs((np.array(mle["v0"]) - scene.truth.v0) / np.array(mle["stderr"]["v0"]))
    assert z.max() < MLE_Z_MAX, z


def cli(*args):
    return subprocess.run([sys.executable, "-m", "cuespin.pipeline.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=600)


def no_nan(const):
    raise AssertionError(f"JSON holds {const}; the contract says null")


@pytest.mark.parametrize("kind", ["case1", "case2", "case3", "case4", "case5", "curved_right", "curved_left"])
def test_end_to_end(tmp_path, kind):
    scene = e2e_scene(kind)
    sf, video = tmp_path / "s.json", tmp_path / "shot.avi"
    write_scene(sf, scene)
    render_video(scene, video)
    res = cli("recover", video, "--scene", sf, "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout, parse_constant=no_nan)
    assert set(out) >= {"video", "track", "methods", "best", "timing_s"}
    assert out["track"]["frames"] == out["track"]["ok_frames"] or kind == "case4"
    truth = scene.truth
    v0, w0, R = np.array(truth.v0), np.array(truth.w0), scene.physics.R
    speed = np.hypot(*v0)
    mle = out["methods"]["mle"]
    assert mle["status"] == "ok", mle["reason"]
    assert mle["model"] == ("rolling" if kind == "case4" else "full")
    for key, true in (("v0", v0), ("w0", w0)):
        z = np.abs((np.array(mle[key]) - true) / np.array(mle["stderr"][key]))
        if kind == "case2" and key == "w0":
            assert R * np.hypot(*(np.array(mle["w0"]) - w0)) / speed < MLE_CASE2_RW_REL
        else:
            assert z.max() < MLE_Z_MAX, (key, z)
    assert abs(mle["t0"] - truth.t0) < 1e-3
    paper = out["methods"]["paper"]
    assert paper["status"] in ("ok", "ambiguous"), paper["reason"]
    sols = [paper] if paper["status"] == "ok" else paper["solutions"]
    best = min(sols, key=lambda s: np.hypot(*(np.array(s["v0"]) - v0)))
    assert np.hypot(*(np.array(best["v0"]) - v0)) / speed < PAPER_V0_REL
    assert R * np.hypot(*(np.array(best["w0"]) - w0)) / speed < PAPER_RW_REL
    assert paper["trajectory"] == ("parabola" if kind.startswith("curved") else "line")
    assert out["best"] == "mle"


def test_recover_method_choice_and_bad_input(tmp_path):
    scene = e2e_scene("curved_right")
    sf, video = tmp_path / "s.json", tmp_path / "shot.avi"
    write_scene(sf, scene)
    render_video(scene, video)
    res = cli("recover", video, "--scene", sf, "--method", "paper")
    assert res.returncode == 0 and "paper" in res.stdout and "mle " not in res.stdout
    bad = cli("recover", tmp_path / "missing.avi", "--scene", sf)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_ar1_bound_at_the_true_correlation_matches_the_errors():
    """The Cramer-Rao bound under AR(1) errors (crb_covariance(ar1=)) at the
    true lag-1 correlation against the MLE's real errors on 40 simulated
    tracks with that correlation (review of the bound: not the fit's own
    estimate, so not a restatement of its standard errors).  Measured: RMS /
    bound 0.88 and 1.04 for v0's components; 40 tracks give each RMS a
    relative standard error of ~11%, so 3 of them either side."""
    from cuespin.data_gen.sampler import sample_shot
    from cuespin.physics import phases
    from cuespin.recover.api import recover_track
    from cuespin.recover.mle import crb_covariance, model_track

    sigma, rho = 1e-4, 0.67
    shot, p = sample_shot(7, "random")
    t = np.arange(0.0, min(phases(shot, p).t2 + 0.3, 4.0), 1 / 240)
    clean = model_track(shot, p, t)
    errs, bound = [], None
    for s in range(40):
        rng = np.random.default_rng(100 + s)
        e = np.zeros((len(t), 2))
        e[0] = sigma * rng.standard_normal(2)
        for k in range(1, len(t)):
            e[k] = rho * e[k - 1] + sigma * np.sqrt(1 - rho**2) * rng.standard_normal(2)
        _, est = recover_track(t, clean + e, np.ones(len(t), bool), np.full(len(t), sigma), p, method="mle",
                               return_estimate=True)
        if est.mle.status != "ok":
            continue
        errs.append(np.asarray(est.mle.v0) - np.asarray(shot.v0))
        if bound is None:
            bound = np.sqrt(np.diag(crb_covariance(shot, p, est.meas, ar1=rho))[3:5])
    assert len(errs) >= 30
    ratio = np.sqrt(np.mean(np.square(errs), axis=0)) / bound
    assert np.all((ratio > 0.67) & (ratio < 1.33)), ratio


def sliding_answers_z(n: int, seed: int, rho: float = 0.0) -> np.ndarray:
    """The MLE's errors in its own standard errors (v0, w0 components; rows
    of shots answered ok with free slip) on ``n`` simulated sliding tracks
    (recover.simulate.sliding_tracks: the sampler's presets, 60-480 fps,
    noise 2e-5-6e-4 m, errors independent or AR(1) of lag-1 ``rho``), each
    fitted with its true per-frame error as the stated one (a lossless
    track: the estimator's own calibration, apart from any tracker's)."""
    from cuespin.recover.estimate import estimate
    from cuespin.recover.simulate import sliding_tracks
    rows = []
    for tr in sliding_tracks(n, seed, rho=rho):
        m = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s, run_paper=False).mle
        if m.status == "ok" and m.model == "full":
            rows.append((np.r_[m.v0, m.w0] - np.r_[tr.shot.v0, tr.shot.w0]) / np.r_[m.stderr["v0"], m.stderr["w0"]])
    return np.array(rows)


@pytest.mark.slow
@pytest.mark.parametrize("rho", [0.0, 0.67])
def test_mle_intervals_cover_on_400_simulated_tracks(rho):
    """Coverage of the 95% intervals and RMS error in stated errors over 408
    simulated sliding tracks, independent errors and AR(1) errors of lag-1
    0.67 (a lossy codec at low noise): separates the estimator's
    calibration from the tracker's stated errors (issue 11).  Measured
    (seed 41; docs/measurements.md, stats7): independent errors, 407 ok,
    coverage 95.9%, RMS 0.98.  Held to the issue's targets, coverage 93-97%
    and RMS 0.9-1.1 (the same tracks each time: only a change of the fit
    moves them)."""
    z = sliding_answers_z(408, 41, rho)
    assert len(z) >= 250, len(z)
    cover = np.mean(np.abs(z) < 1.959964)
    rms = np.sqrt(np.mean(z**2))
    print(f"rho {rho}: {len(z)} ok with free slip, coverage {cover:.1%}, RMS / stated {rms:.3f}")
    assert 0.93 <= cover <= 0.97 and 0.9 <= rms <= 1.1, (len(z), cover, rms)
