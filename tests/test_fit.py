"""fit/: strike, breakpoint and rest; the parabola/line decision."""

import numpy as np
import pytest

from cuespin.data_gen.sampler import sample_shot
from cuespin.fit.decide import sliding_ended
from cuespin.fit.conics import classify_path, fit_line, parabola_distances
from cuespin.fit.segment import noise_from_track, segment_track
from cuespin.physics import phases, positions, rolling_deceleration, sliding_parabola

# Position noise of a ~0.01 px centroid at 500 px/m (the tracker's tier).
SIGMA_M = 2e-5
# Measured over these seeds at SIGMA_M and 240 fps: strike time within 5e-5 s
# (1/80 frame), breakpoint within 1.5e-3 s except where sliding is invisible.
T0_TOL_S = 2e-4
T1_TOL_S = 1e-2


def noisy_track(shot, params, fps=240.0, seed=0, sigma=SIGMA_M, t_max=6.0):
    ph = phases(shot, params)
    t = np.arange(0.0, min(ph.t2 + 0.4, t_max), 1.0 / fps)
    xy = positions(shot, params, t, ph)
    rng = np.random.default_rng(seed)
    return t, xy + sigma * rng.standard_normal(xy.shape), ph


@pytest.mark.parametrize("preset", ["case1", "case2", "case3", "case5", "masse", "random"])
def test_segmentation_finds_strike_and_breakpoint(preset):
    shot, params = sample_shot(21, preset)
    t, xy, ph = noisy_track(shot, params)
    seg = segment_track(t, xy, rolling_deceleration(params.mu_r, params.g), SIGMA_M)
    assert seg, seg.reason
    assert seg.t0 == pytest.approx(shot.t0, abs=T0_TOL_S)
    np.testing.assert_allclose(seg.x0, shot.x0, atol=5 * SIGMA_M)
    if ph.t1 < t[-1] - 0.05:
        assert seg.t1 == pytest.approx(ph.t1, abs=T1_TOL_S)
    else:
        assert not np.isfinite(seg.t1) or seg.t1 == pytest.approx(ph.t1, abs=T1_TOL_S)
    assert seg.sigma == pytest.approx(SIGMA_M, rel=0.15)
    if ph.t2 < t[-1] - 0.1:  # rest in view
        assert seg.x2 is not None
        np.testing.assert_allclose(seg.x2, ph.x2, atol=5 * SIGMA_M)


def test_rolling_from_the_strike_alternative():
    # The segmentation keeps the rolling-from-the-strike fit beside its
    # sliding one; fit.decide chooses (tests/test_decide.py).
    shot, params = sample_shot(22, "case4")
    t, xy, ph = noisy_track(shot, params)
    seg = segment_track(t, xy, rolling_deceleration(params.mu_r, params.g), SIGMA_M)
    roll = seg.rolling
    assert roll and roll.t1 == roll.t0
    assert roll.t0 == pytest.approx(shot.t0, abs=T0_TOL_S)
    np.testing.assert_allclose(roll.v0, shot.v0, rtol=1e-3)


def test_track_ending_while_sliding():
    shot, params = sample_shot(23, "masse")
    t, xy, ph = noisy_track(shot, params)
    cut = t < shot.t0 + 0.5 * (ph.t1 - shot.t0)
    seg = segment_track(t[cut], xy[cut], rolling_deceleration(params.mu_r, params.g), SIGMA_M)
    assert seg and not sliding_ended(seg, t[cut])


def test_noise_estimate_from_track():
    shot, params = sample_shot(24, "case3")
    t, xy, _ = noisy_track(shot, params, sigma=3e-5)
    assert noise_from_track(xy) == pytest.approx(3e-5, rel=0.1)


@pytest.mark.parametrize("seed", range(25, 31))
def test_strike_found_when_still_frames_scatter_more_than_stated(seed):
    # A lossy codec scatters a still ball's centre by several stated errors
    # (measured: ~3x with MJPG at sigma 2); one frame far out must not pass
    # for the strike either.  (Measured: t0 within 6e-5 s, x0 within 2 of
    # the scattered errors over these seeds.)
    shot, params = sample_shot(seed, "case3")
    t, xy, ph = noisy_track(shot, params, sigma=3 * SIGMA_M)
    xy[1] += 8 * SIGMA_M
    seg = segment_track(t, xy, rolling_deceleration(params.mu_r, params.g), SIGMA_M)
    assert seg, seg.reason
    assert seg.t0 == pytest.approx(shot.t0, abs=3 * T0_TOL_S)  # 3x the noise: 3x the tier
    np.testing.assert_allclose(seg.x0, shot.x0, atol=15 * SIGMA_M)


def test_bad_tracks_fail_with_reasons():
    assert not segment_track(np.arange(5) / 60, np.zeros((5, 2)), 0.07, 1e-5)
    t = np.arange(100) / 60
    still = segment_track(t, np.full((100, 2), 0.5) + 1e-6 * np.random.default_rng(0).standard_normal((100, 2)), 0.07, 1e-6)
    assert not still and "does not move" in still.reason


@pytest.mark.parametrize("seed", range(4))
def test_fitted_parabola_holds_the_sliding_path(seed):
    shot, params = sample_shot(30 + seed, "masse")
    t, xy, ph = noisy_track(shot, params)
    slide = (t > shot.t0) & (t < ph.t1)
    true = sliding_parabola(shot.x0, shot.v0, shot.w0, params)
    # Start from a perturbed parabola: the fit must find its way back.
    from cuespin.physics.parabola import Parabola
    start = Parabola(a=true.a * 1.3, theta=true.theta + 0.05, vertex=true.vertex + 0.01)
    shape = classify_path(xy[slide], start)
    assert shape.curved
    par = shape.parabola.parabola
    # The fit holds the noise-free sliding path to a few noise sigmas, and its
    # residuals are the noise.
    clean = positions(shot, params, t[slide])
    assert np.abs(parabola_distances(par, clean)).max() < 4 * SIGMA_M
    assert np.std(shape.parabola.residuals) == pytest.approx(SIGMA_M, rel=0.15)


@pytest.mark.parametrize("seed,max_nfev", [(30, 12), (31, 200)])
def test_parabola_fit_is_least_squares(seed, max_nfev, monkeypatch):
    # fit.lm.lm_fit is least_squares' lm call without its wrapper (MINPACK's
    # own scaling, as least_squares' default x_scale): the same fit to the
    # last bit, capped (the path's shape) and run to convergence (the paper's).
    from scipy.optimize import least_squares

    import cuespin.fit.conics as conics
    from cuespin.physics.parabola import Parabola
    shot, params = sample_shot(seed, "masse")
    t, xy, ph = noisy_track(shot, params)
    slide = (t > shot.t0) & (t < ph.t1)
    true = sliding_parabola(shot.x0, shot.v0, shot.w0, params)
    start = Parabola(a=true.a * 1.3, theta=true.theta + 0.05, vertex=true.vertex + 0.01)
    new = conics.fit_parabola(xy[slide], start, max_nfev)

    def lm_fit(resid, p0, jac, x_scale, ftol, xtol, max_nfev):
        return least_squares(resid, p0, jac=jac, method="lm", xtol=xtol, ftol=ftol, max_nfev=max_nfev)
    monkeypatch.setattr(conics, "lm_fit", lm_fit)
    old = conics.fit_parabola(xy[slide], start, max_nfev)
    assert new.ok and old.ok
    assert (new.parabola.a, new.parabola.theta) == (old.parabola.a, old.parabola.theta)
    for a, b in ((new.parabola.vertex, old.parabola.vertex), (new.residuals, old.residuals), (new.cov, old.cov)):
        assert np.array_equal(a, b)


def test_parabola_jacobian_is_the_distances_derivative():
    # The fit's analytic Jacobian (fit.conics.parabola_jacobian) against
    # central differences of the orthogonal distances, points either side
    # of the curve and across the vertex.
    from cuespin.fit.conics import parabola_jacobian
    from cuespin.physics.parabola import Parabola
    rng = np.random.default_rng(0)
    par = Parabola(a=3.0, theta=0.7, vertex=np.array([0.5, 0.3]))
    x = np.linspace(-0.3, 0.4, 25)
    p = par.to_table(np.stack([x, 3.0 * x**2], 1)) + rng.normal(0, 0.01, (25, 2))
    q = np.r_[np.log(par.a), par.theta, par.vertex]

    def d(q):
        return parabola_distances(Parabola(a=float(np.exp(q[0])), theta=float(q[1]), vertex=q[2:4]), p)

    h = 1e-7
    num = np.stack([(d(q + h * e) - d(q - h * e)) / (2 * h) for e in np.eye(4)], 1)
    assert np.abs(parabola_jacobian(par, p) - num).max() < 1e-7


def test_straight_path_is_a_line():
    shot, params = sample_shot(40, "case3")
    t, xy, ph = noisy_track(shot, params)
    slide = (t > shot.t0) & (t < ph.t1)
    # Any start: a straight path must not be called curved.
    from cuespin.physics.parabola import Parabola
    d = fit_line(xy[slide]).direction
    start = Parabola(a=5.0, theta=np.arctan2(d[1], d[0]), vertex=xy[slide][0])
    shape = classify_path(xy[slide], start)
    assert not shape.curved and shape.p_value >= 0.01
    assert np.std(shape.line.residuals) == pytest.approx(SIGMA_M, rel=0.3)


def test_rest_not_ended_by_one_far_frame():
    # A resting ball's frame lies 5 sigma from the median of the last frames
    # about once in 10^4; at 480 fps a rest of hundreds of frames then ended
    # there, and a case-2 slide fitted through the still frames before it put
    # its stop 6-40 of its errors past the rest (calibrate_tests.py --which
    # case2: 2 tracks of 1,200).  One far frame no longer ends the rest; two
    # in a row do.
    from cuespin.fit.segment import find_rest_end
    rng = np.random.default_rng(3)
    sigma = 1e-4
    n_move, n_rest = 100, 300
    t = np.arange(n_move + n_rest) / 480.0
    xy = np.zeros((len(t), 2))
    xy[:n_move, 0] = -0.5 * 2.0 * (t[n_move] - t[:n_move]) ** 2   # decelerating to a stop at t[n_move]
    xy += sigma * rng.standard_normal(xy.shape)
    k = find_rest_end(t, xy, sigma)
    assert abs(k - n_move) <= 20                                    # within the creep to the stop
    xy[n_move + 150] = [6 * sigma, 0.0]                             # one far frame in the rest
    assert find_rest_end(t, xy, sigma) == k
    xy[n_move + 151] = [6 * sigma, 0.0]                             # two: the rest starts after them
    assert find_rest_end(t, xy, sigma) == n_move + 152


# Breakpoint error (frames) within which the sliding fit's t1 lies on
# benchmarks/short_slide.py's shots named below, rest in view (measured
# with SLIDE_DECEL_RATIO 5: 0.97, 0.24 and 3.24 frames; before it 784,
# 0.73 and 891).
KNOWN_SHOT_T1_FRAMES = 5.0


@pytest.mark.parametrize("k, held", [(27, False), (91, False), (125, True)])
def test_sliding_arc_does_not_run_on_into_the_rolling(k, held):
    # benchmarks/short_slide.py's generator with the rest in view (seed 5:
    # case 4 given a slip of 0.2-8 frames): with a_s free, "sliding" at
    # rolling's deceleration is rolling, and the profile's minimum fell 3-7 s
    # into the rolling (shots 27 and 125; arc9's paper answers 196% and 264%
    # off).  Shot 91: with the rule on breakpoints in view alone, the
    # still-sliding fit at rolling's deceleration took over and ran into the
    # rest as case 2 over 2223 frames.  The arc must end near the true t1.
    # Shot 125's (3.2 frames at 120 fps, 6e-4 m) is held on the rule's bound
    # and says so (t1_bound; its paper answer refused as not identified);
    # 27's and 91's are free of it (|a_s| 29.1 and 12.2 times rolling's).
    from tests.test_recover import short_slide_shot
    tr, p, sigma, exposure, _ = short_slide_shot(5, k)
    decel = rolling_deceleration(p.mu_r, p.g)
    seg = segment_track(tr.t, tr.xy, decel, sigma, exposure)
    t1_true = phases(tr.shot, p).t1
    assert abs(seg.t1 - t1_true) * tr.fps < KNOWN_SHOT_T1_FRAMES, (seg.t1, t1_true)
    assert seg.t1_bound == held, np.hypot(*seg.a_slide) / decel


# Where mu_s g is under SLIDE_DECEL_RATIO times the rolling deceleration the
# rule cannot hold a slide's |a_s| and moves t1 earlier (review 11a,
# sample_shot(5, "random") with mu_s 0.1 and mu_r set to the ratio, 12
# tracks at 120/240 fps, 2e-5-6e-4 m: at true ratio 4 t1 -5.3 frames in
# median, 4 of 12 more than 10 off, up to 28).  A breakpoint off by more
# than KNOWN_SHOT_T1_FRAMES must say it is held on the bound (this test's
# draw, rng(5) for each ratio, at ratio 4: 11 of 12 held, errors to 264
# frames; the one free 0.9 frames off; the review's draw 12 of 12), and a
# slide above the ratio must not be held (5.5: 0 of 12, t1 within 2.9).
@pytest.mark.slow
@pytest.mark.parametrize("ratio_true, held", [(5.5, False), (4.0, True)])
def test_slide_below_the_deceleration_ratio_is_not_identified(ratio_true, held):
    import dataclasses
    from cuespin.data_gen.sampler import sample_shot
    from cuespin.fit.decide import sliding_ended
    from cuespin.recover.simulate import simulate_track
    rng = np.random.default_rng(5)
    for i in range(12):
        shot, p = sample_shot(rng, "random")
        p = dataclasses.replace(p, mu_s=0.1, mu_r=0.1 * 7 / (5 * ratio_true))
        fps, sigma = (120.0, 240.0)[i % 2], (2e-5, 1e-4, 6e-4)[i % 3]
        tr = simulate_track(shot, p, fps, sigma, rng, 0.0)
        seg = segment_track(tr.t, tr.xy, rolling_deceleration(p.mu_r, p.g), sigma, 0.0)
        off = abs(seg.t1 - phases(shot, p).t1) * fps
        if not held:
            assert not seg.t1_bound and off < KNOWN_SHOT_T1_FRAMES, (i, off)
        else:
            assert seg.t1_bound or off < KNOWN_SHOT_T1_FRAMES, (i, off)
            if seg.t1_bound and seg.t2 is None:  # no rest in view: its end is not identified
                assert not sliding_ended(seg, tr.t)


# recover.simulate.short_slip_tracks(frames=(0.2, 8.0), to_rest=True), 120
# tracks (60-240 fps, 2e-5-6e-4 m): breakpoints more than
# SLIP_T1_FAR_FRAMES frames from the true t1.  The rate is measured on seed
# 42 (1 of 120, the largest 10.6 frames; seg12) and asserted on seed 41,
# the test's (before / after SLIDE_DECEL_RATIO: 8 / 2 of 120; the largest
# 1630 -> 14.4 frames, at 240 fps and 6e-4 m, where a slip under a frame is
# not seen; 27 s CPU).
SLIP_T1_FAR_FRAMES = 10.0
SLIP_T1_FAR_RATE = 1 / 120
# No arc runs on this far past the true end of sliding (before the rule: up
# to 1630 frames on this set, 2223 on short_slide.py's seeds 5 and 6).
SLIP_T1_RUNAWAY_FRAMES = 25.0


@pytest.mark.slow
def test_breakpoint_error_on_short_slides_seen_to_rest():
    from cuespin.recover.simulate import short_slip_tracks
    n, far, worst = 120, 0, 0.0
    for tr in short_slip_tracks(n, 41, frames=(0.2, 8.0), to_rest=True):
        p = tr.params
        seg = segment_track(tr.t, tr.xy, rolling_deceleration(p.mu_r, p.g), tr.sigma, tr.exposure_s)
        err = abs(seg.t1 - phases(tr.shot, p).t1) * tr.fps
        far += err > SLIP_T1_FAR_FRAMES
        worst = max(worst, err)
    assert worst < SLIP_T1_RUNAWAY_FRAMES
    # Within two binomial standard errors of the measured rate.
    assert far / n <= SLIP_T1_FAR_RATE + 2 * np.sqrt(SLIP_T1_FAR_RATE * (1 - SLIP_T1_FAR_RATE) / n)


def test_the_strike_times_share_left_out_only_where_the_strike_is_not_in_view():
    # fit.segment._geometry_cov, rolling from the strike (t1 = t0): x0
    # carries t0's error from the profile's curvature a frame either side;
    # where the profile does not curve there (d2 <= 0) the share is left
    # out.  Measured: never with the strike in
    # view (360 simulated case-4 tracks, 40 realistic H.264); on tracks cut
    # to begin after the strike (2 of 30 at 0.5 frame: seed 5's tracks 15
    # and 24), where no still frame holds x0 and the paper's answer, which
    # needs x0, is refused: so no answer is given on errors missing the share.
    from cuespin.recover.estimate import estimate
    from cuespin.recover.simulate import rolls_to_rest_tracks
    tracks = list(rolls_to_rest_tracks(25, 5, presets=("case4",)))
    for i, cut, curved in ((24, 0.0, True), (24, 0.5, False)):
        tr = tracks[i]
        k = tr.t > tr.shot.t0 + (cut / tr.fps - 1e-12 if cut else -np.inf)
        est = estimate(tr.t[k], tr.xy[k], np.full(k.sum(), tr.sigma), tr.params, tr.exposure_s)
        g = est.seg.geometry_cov
        assert est.seg.t1 == est.seg.t0, (i, cut)
        assert bool(np.any(g["x0_t0"])) is curved
        if not curved:
            assert est.paper.status == "degenerate" and "strike is not in view" in est.paper.reason, est.paper.reason


def test_a_rest_before_the_motion_counts_no_frames_of_motion():
    # held52's 52/32: a rest given before the motion's start gave the
    # reason "only -32 frames of motion".
    from cuespin.fit.segment import segment_track
    t = np.arange(40) / 60.0
    xy = np.zeros((40, 2))
    xy[20:, 0] = 0.01 * np.arange(20)
    seg = segment_track(t, xy, 0.1, sigma=1e-4, frames=(20, 5))
    assert not seg and "only 0 frames of motion" in seg.reason, seg.reason
