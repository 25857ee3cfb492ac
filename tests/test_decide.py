"""fit/decide.py: each decision's false-positive rate, measured on tracks
simulated under its null hypothesis with the project's own generator
(recover.simulate: the forward model plus Gaussian noise, frame rates
60-480, noise 2e-5-6e-4 m), held to the nominal rate plus two binomial
standard errors.  The 400-track runs are slow; the default run keeps a
smaller version of each."""

import numpy as np
import pytest

from cuespin.data_gen.sampler import sample_shot
from cuespin.fit.decide import LEVEL, sliding_ended
from cuespin.fit.segment import correlated_end_F, segment_track
from cuespin.physics import phases, rolling_deceleration
from cuespin.recover.estimate import estimate
from cuespin.recover.mle import model_track, time_correlation, time_whitener
from cuespin.recover.paper import path_shape
from cuespin.recover.simulate import (FPS_GRID, SIGMA_GRID_M, ar1_errors, mixed_tracks, null_rolling_tracks,
                                      shared_errors, simulate_track, sliding_tracks)


def allowed(n: int, level: float = LEVEL) -> int:
    """Most false positives in ``n`` null tracks within nominal + 2 binomial SE."""
    return int(np.floor(n * (level + 2 * np.sqrt(level * (1 - level) / n))))


def false_sliding(n, seed):
    cells = {}
    for tr in null_rolling_tracks(n, seed):
        est = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s,
                       run_paper=False)
        cells.setdefault((tr.fps, tr.sigma), []).append(bool(est.decisions["sliding_seen"]))
    return cells


def test_false_sliding_rate_small():
    cells = false_sliding(40, 100)
    hits = sum(sum(v) for v in cells.values())
    assert hits <= allowed(40), cells


@pytest.mark.slow
def test_false_sliding_rate_400_every_cell():
    cells = false_sliding(408, 7)
    hits = sum(sum(v) for v in cells.values())
    assert hits <= allowed(408), hits
    for k, v in cells.items():  # every frame rate and noise level
        assert sum(v) <= allowed(len(v)), (k, sum(v), len(v))


def mid_slide_draws(n, seed, fps_grid=FPS_GRID):
    """``n`` shots that end while the ball still slides (masse and random
    shots, cut 40-95% of the way through sliding), one per frame rate and
    noise level in turn: ``(rng, shot, params, fps, sigma, exposure_s,
    cut)``; the caller draws the errors from ``rng`` before the next."""
    rng = np.random.default_rng(seed)
    i = 0
    while i < n:
        fps = fps_grid[i % len(fps_grid)]
        sigma = SIGMA_GRID_M[(i // len(fps_grid)) % len(SIGMA_GRID_M)]
        shot, p = sample_shot(rng, ("masse", "random")[i % 2])
        ph = phases(shot, p)
        if ph.t1 - shot.t0 < 12 / fps:
            continue
        cut = shot.t0 + float(rng.uniform(0.4, 0.95)) * (ph.t1 - shot.t0)
        exposure = float(rng.uniform(0.3, 1.0) / fps) if rng.random() < 0.5 else 0.0
        i += 1
        yield rng, shot, p, fps, sigma, exposure, cut


def still_sliding_tracks(n, seed):
    """Tracks of :func:`mid_slide_draws` with independent errors."""
    for rng, shot, p, fps, sigma, exposure, cut in mid_slide_draws(n, seed):
        yield simulate_track(shot, p, fps, sigma, rng, exposure, t_end=cut)


def false_ended(n, seed):
    hits = 0
    for tr in still_sliding_tracks(n, seed):
        p = tr.params
        seg = segment_track(tr.t, tr.xy, rolling_deceleration(p.mu_r, p.g), tr.sigma, tr.exposure_s)
        hits += bool(seg) and sliding_ended(seg, tr.t).yes
    return hits


def test_false_sliding_ended_rate_small():
    assert false_ended(40, 200) <= allowed(40)


@pytest.mark.slow
def test_false_sliding_ended_rate_400():
    assert false_ended(400, 8) <= allowed(400)


# The AR(1) errors' lag-1 correlation in the correlated "sliding ended"
# tests: a lossy codec at low noise (0.67 measured on MJPG, recover.mle's
# MAX_AR1 comment).
END_TEST_RHO = 0.7


def correlated_still_sliding_tracks(n, seed, errors, fps_grid=FPS_GRID):
    """``n`` tracks cut mid-slide (as :func:`still_sliding_tracks` draws
    them) whose errors are correlated in time: ``errors`` "codec" (an
    inter-frame codec's whole error, recover.mle.INTER_CODEC_ACF,
    recover.simulate.shared_errors) or "ar1" (AR(1), lag-1
    :data:`END_TEST_RHO`).  Yields ``(t, xy, params, sigma, exposure_s,
    whiten, shot)``, ``whiten`` that correlation's (recover.mle.time_whitener)."""
    for rng, shot, p, fps, sigma, exposure, cut in mid_slide_draws(n, seed, fps_grid):
        t = np.arange(0, np.floor(cut * fps) + 1) / fps
        if errors == "codec":
            e, whiten = shared_errors(len(t), fps, rng), time_whitener()
        else:
            e, whiten = ar1_errors(len(t), END_TEST_RHO, rng), time_whitener(rho=END_TEST_RHO, frame_dt=1 / fps)
        yield t, model_track(shot, p, t, exposure) + sigma * e, p, sigma, exposure, whiten, shot


def false_ended_correlated(n, seed, errors, fps_grid=FPS_GRID):
    """False "sliding ended" on :func:`correlated_still_sliding_tracks`,
    decided under their correlation (fit.segment.correlated_end_F), as
    recover.estimate asks it."""
    hits = 0
    for t, xy, p, sigma, exposure, whiten, _ in correlated_still_sliding_tracks(n, seed, errors, fps_grid):
        seg = segment_track(t, xy, rolling_deceleration(p.mu_r, p.g), sigma, exposure)
        hits += bool(seg) and sliding_ended(seg, t, end_F=correlated_end_F(seg, t, xy, whiten)).yes
    return hits


def test_estimate_withholds_w0_of_a_codec_track_cut_mid_slide():
    # The 17th of test_false_sliding_ended_rate_codec_480fps_small's tracks:
    # with the segmentation's end_F, recover.estimate read "ended" (F 9.35
    # against 6.69) and stated w0 (70.6, 44.0) rad/s for the true (185.9,
    # 83.0); under the codec's correlation its slide runs to the end.
    tracks = correlated_still_sliding_tracks(17, 202, "codec", fps_grid=(480.0,))
    t, xy, p, sigma, exposure, _, _ = list(tracks)[-1]
    est = estimate(t, xy, np.full(len(t), sigma), p, exposure, lossless=False, inter_frame=True,
                   run_paper=False)
    assert not est.decisions["sliding_ended"]
    assert est.mle.status == "degenerate", est.mle.status


def test_correlated_end_F_is_end_F_for_independent_errors():
    tr = next(still_sliding_tracks(1, 3))
    p = tr.params
    seg = segment_track(tr.t, tr.xy, rolling_deceleration(p.mu_r, p.g), tr.sigma, tr.exposure_s)
    F = correlated_end_F(seg, tr.t, tr.xy, lambda tf, M: M)
    assert np.isclose(F, seg.end_F, rtol=1e-6, atol=1e-9), (F, seg.end_F)


@pytest.mark.parametrize("kw", [{}, {"rho": 0.7, "frame_dt": 1 / 240}])
def test_time_whitener_is_the_cholesky_whitening(kw):
    # The O(k) Kalman whitening against L^-1 M by the k x k Cholesky factor,
    # on frames at irregular times (a track with frames lost).
    rng = np.random.default_rng(4)
    t = np.sort(rng.choice(np.arange(600) / 240, 300, replace=False))
    M = rng.standard_normal((300, 5))
    L = np.linalg.cholesky(time_correlation(t, **kw))
    assert np.allclose(time_whitener(**kw)(t, M), np.linalg.solve(L, M), atol=1e-10)


@pytest.mark.parametrize("kw", [{}, {"rho": 0.7, "frame_dt": 1 / 240}])
def test_time_whitener_whitens_columns_alike_together_or_apart(kw):
    # correlated_end_F whitens both fits' columns in one call: each column
    # must come out with the same bits as alone (the filter's gains are the
    # times' alone; every operation on the rows is elementwise).
    rng = np.random.default_rng(5)
    t = np.sort(rng.choice(np.arange(600) / 240, 300, replace=False))
    M = rng.standard_normal((300, 10))
    whiten = time_whitener(**kw)
    together = whiten(t, M)
    assert all(np.array_equal(together[:, [j]], whiten(t, M[:, [j]])) for j in range(10))
    assert np.array_equal(together[:, :5], whiten(t, M[:, :5]))




def _numpy_kalman_gains(t, var, tc, white):
    """time_whitener's filter as it was written on numpy arrays (the (c, c)
    state covariance): each frame's transitions, gains and innovations'
    standard deviations, the reference for the Python-float recursion."""
    phis, gains, roots = np.ones((len(t), len(var))), np.empty((len(t), len(var))), np.empty(len(t))
    P = np.diag(var)
    for k in range(len(t)):
        if k:
            phi = np.exp(-(t[k] - t[k - 1]) / tc)
            phis[k] = phi
            P = phi[:, None] * P * phi[None, :] + np.diag(var * (1.0 - phi**2))
        S = P.sum() + white
        g = P.sum(axis=1) / S
        roots[k], gains[k] = np.sqrt(S), g
        P = P - S * np.outer(g, g)
    return phis, gains, roots


def test_time_whitener_gains_in_floats_are_the_arrays_bits():
    # The filter's covariance recursion in Python floats (recover.mle._kalman_gains)
    # gives the bits of the same operations on numpy's (c, c) arrays, for both
    # forms (the codec's two components, AR(1)'s one), on irregular and regular
    # frame times (recspeed: 0 of 300 random whitenings differed).
    from cuespin.recover.mle import INTER_CODEC_ACF, _kalman_gains

    rng = np.random.default_rng(6)
    a, b, tau, tau_long = INTER_CODEC_ACF
    forms = [(np.array([a, b]), np.array([tau_long, tau]), 1.0 - a - b),
             (np.array([1.0]), np.array([-1 / 240 / np.log(0.7)]), 0.0)]
    for var, tc, white in forms:
        for t in (np.sort(rng.choice(np.arange(600) / 240, 300, replace=False)), np.arange(90) / 60, np.zeros(1)):
            mine = _kalman_gains(t[1:] - t[:-1], var, tc, white)
            assert all(np.array_equal(x, y) for x, y in zip(mine, _numpy_kalman_gains(t, var, tc, white)))

def test_time_correlation_kept_is_the_same_and_not_shared():
    # time_correlation keeps its last matrices (a recovery asks for the
    # same frames' several times): a caller's write (shared_rho zeroes the
    # diagonal) must not reach the next caller, the answer must be the one
    # made afresh, and longer tracks than it keeps are made every time.
    import cuespin.recover.mle as mle
    t = np.arange(50) / 60.0
    first = time_correlation(t)
    first[:] = 7.0
    again = time_correlation(t)
    assert np.all(np.diag(again) == 1.0) and np.all(again <= 1.0)
    assert np.array_equal(again, mle._time_correlation.__wrapped__((t.tobytes(), tuple(mle.INTER_CODEC_ACF),
                                                                       None, None)))
    assert np.allclose(time_correlation(t, rho=0.5, frame_dt=1 / 60), 0.5 ** np.abs(np.subtract.outer(t, t)
                                                                                        * 60))
    long = np.arange(mle.KEPT_CORRELATION_FRAMES + 1) / 240.0
    assert time_correlation(long[:5]).shape == (5, 5)
    assert time_correlation(long).shape == (len(long),) * 2


def test_false_sliding_ended_rate_codec_480fps_small():
    # 480 fps: the worst frame rate under the codec's correlation (8.2% with
    # independent errors' end_F; docs/measurements.md, gross13 and endf13).
    # These 100 tracks: 4 "ended" with seg.end_F (allowed 2), 0 with
    # correlated_end_F.
    assert false_ended_correlated(100, 202, "codec", fps_grid=(480.0,)) <= allowed(100)


@pytest.mark.slow
@pytest.mark.parametrize("errors", ["codec", "ar1"])
def test_false_sliding_ended_rate_correlated_400(errors):
    assert false_ended_correlated(400, 9, errors) <= allowed(400)


def false_curved(n, seed):
    hits = total = 0
    for tr in sliding_tracks(n, seed, presets=("case1", "case3", "case5")):
        p = tr.params
        seg = segment_track(tr.t, tr.xy, rolling_deceleration(p.mu_r, p.g), tr.sigma, tr.exposure_s)
        shape = path_shape(seg, tr.xy, p) if seg else None
        if shape is not None:
            total += 1
            hits += shape.curved
    return hits, total


def test_false_curved_rate_small():
    hits, total = false_curved(48, 300)
    assert total >= 30 and hits <= allowed(total)


@pytest.mark.slow
def test_false_curved_rate_400():
    hits, total = false_curved(440, 9)
    assert total >= 400 and hits <= allowed(total)


@pytest.mark.slow
def test_false_sliding_rate_under_ar1_errors_every_cell():
    # Errors correlated along the track (AR(1), lag-1 0.67: MJPG at low
    # noise, README): the fit models them (recover.mle, ar1) and the slip
    # test keeps its nominal rate within two binomial standard errors overall,
    # at every frame rate and at every noise level (before the AR(1) model,
    # with the HAC rescaling alone: 78 of 408, 19%).  Measured (seed 7): 3 of
    # 408, 2 of them in one frame-rate x noise cell of 34 (240 fps, 6e-4 m:
    # LR 10.8 and 11.7 against 9.2), which a per-cell bound of 1 would fail
    # about a third of the time at the nominal rate itself over 12 cells; so
    # the cells are held to it pooled by frame rate and by noise (102 and
    # 136 tracks each).
    cells = {}
    for tr in null_rolling_tracks(408, 7, rho=0.67):
        est = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s,
                       run_paper=False)
        cells.setdefault((tr.fps, tr.sigma), []).append(bool(est.decisions.get("sliding_seen")))
    hits = sum(sum(v) for v in cells.values())
    assert hits <= allowed(408), hits
    for axis in (0, 1):  # every frame rate, every noise level
        for level in {k[axis] for k in cells}:
            v = [x for k, vs in cells.items() if k[axis] == level for x in vs]
            assert sum(v) <= allowed(len(v)), (axis, level, sum(v), len(v))



# Frame rates of the codec tests of the slip decision (the realistic
# renders' 60-240 fps; 480 fps tracks cost twice as long).
CODEC_SLIP_FPS = (60.0, 120.0, 240.0)
# The drift's time constant (s) and variance (in the pooled model's whole
# error's): cov11's and fixss's extra AR(1) on realistic H.264.
DRIFT_S, DRIFT_VAR = 0.2, 1.0


def codec_drift_null(n, seed):
    """Rolling-from-the-strike tracks (:func:`null_rolling_tracks`, 60-240
    fps) fitted as an inter-frame codec's, whose errors are larger than the
    pooled model states: its whole error (2 sigma, recover.mle.INTER_CODEC_ACF)
    plus a drift of :data:`DRIFT_S` of :data:`DRIFT_VAR` times its variance,
    as realistic H.264 tracks drift (docs/measurements.md cov11, fixss).
    Yields ``(fps, Estimate)``."""
    rng = np.random.default_rng(seed + 1000)
    for tr in null_rolling_tracks(n, seed, fps_grid=CODEC_SLIP_FPS):
        k = len(tr.t)
        err = 2.0 * tr.sigma * (shared_errors(k, tr.fps, rng)
                                + np.sqrt(DRIFT_VAR) * ar1_errors(k, np.exp(-1.0 / (DRIFT_S * tr.fps)), rng))
        xy = model_track(tr.shot, tr.params, tr.t, tr.exposure_s) + err
        yield tr.fps, estimate(tr.t, xy, np.full(k, tr.sigma), tr.params, tr.exposure_s, lossless=False,
                               inter_frame=True, run_paper=False)


def test_false_sliding_rate_codec_drift_small(monkeypatch):
    # The slip's likelihood ratio carries the track's own widening
    # (recover.mle.error_factor), as its standard errors do.  Measured
    # (docs/measurements.md, slipscale): these 16 tracks 0 free slip (3
    # with the pooled sandwich's division alone, allowed 0); 15 widened.
    # The factor counted is the ratio's own, of the free-slip fit (slip_lr's
    # error_factor), not the chosen fit's (MLEResult.error_scale).
    import cuespin.recover.estimate as estimate_module
    from cuespin.recover.mle import error_factor, slip_lr
    factors = []

    def recorded(full, roll, meas=None, codec=None, hac=None):
        factors.append(error_factor(full, meas, codec))
        return slip_lr(full, roll, meas, codec, hac)
    monkeypatch.setattr(estimate_module, "slip_lr", recorded)
    ests = [e for _, e in codec_drift_null(16, 60)]
    hits = sum(bool(e.decisions["sliding_seen"]) for e in ests)
    assert hits <= allowed(16), hits
    assert len(factors) == sum(e.decisions.get("sliding_seen") is not None for e in ests)
    assert sum(f > 1 for f in factors) >= 8  # the drift is seen: the ratio's factor is exercised


@pytest.mark.slow
def test_false_sliding_rate_codec_drift_400_every_frame_rate():
    # Measured (docs/measurements.md, slipscale, seed 60, in-sample: the
    # factor was chosen on it; held out, fixslip: seed 64 5 of 404): 5 of 402 (1.2%;
    # allowed 8), 1 / 1 / 3 of 134 at 60 / 120 / 240 fps (allowed 3 each);
    # with the pooled sandwich's division alone 37 (9.2%): 8 / 12 / 17.
    cells = {}
    for fps, est in codec_drift_null(402, 60):
        cells.setdefault(fps, []).append(bool(est.decisions["sliding_seen"]))
    hits = sum(sum(v) for v in cells.values())
    assert hits <= allowed(402), hits
    for fps, v in cells.items():
        assert sum(v) <= allowed(len(v)), (fps, sum(v), len(v))

def false_autocorrelated(n, seed):
    """Tracks with independent errors (rolling from the strike and sliding,
    alternately; every other pair fitted as a lossy codec's) on which the
    residuals were judged autocorrelated (the AR(1) refit), per cell."""
    cells = {}
    for i, tr in enumerate(mixed_tracks(n, seed)):
        est = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s,
                       lossless=i % 4 < 2, run_paper=False)
        cells.setdefault((tr.fps, tr.sigma), []).append(bool(est.decisions.get("autocorrelated")))
    return cells


def test_false_autocorrelated_rate_small():
    cells = false_autocorrelated(24, 11)
    assert sum(sum(v) for v in cells.values()) <= allowed(24)


@pytest.mark.slow
def test_false_autocorrelated_rate_400_every_cell():
    # Measured (seed 12): see fit.decide.AR1_FACTOR for the 1,200-track run.
    cells = false_autocorrelated(408, 12)
    hits = sum(sum(v) for v in cells.values())
    assert hits <= allowed(408), hits
    for k, v in cells.items():
        assert sum(v) <= allowed(len(v)), (k, sum(v), len(v))


def false_stop_apart(n, seed):
    """Case-2 tracks (sliding runs into the rest) whose segmentation runs
    into the rest, and how many of them the case-2 test calls apart."""
    from cuespin.fit.decide import stop_apart
    from cuespin.recover.paper import case2_distance, geometry_covariance, ran_into_rest
    from cuespin.recover.simulate import case2_tracks
    hits = total = 0
    for tr in case2_tracks(n, seed):
        p = tr.params
        seg = segment_track(tr.t, tr.xy, rolling_deceleration(p.mu_r, p.g), tr.sigma, tr.exposure_s)
        s = seg if seg and ran_into_rest(seg) else (seg.unended if seg else None)
        if s is not None and ran_into_rest(s):
            total += 1
            hits += stop_apart(case2_distance(s, geometry_covariance(s, tr.sigma, True))).yes
    return hits, total


def test_false_stop_apart_rate_small():
    hits, total = false_stop_apart(48, 21)
    assert total >= 40 and hits <= allowed(total)


@pytest.mark.slow
def test_false_stop_apart_rate_400():
    # seed 31: fresh (CASE2_FACTOR was chosen after a failure on seed 22)
    hits, total = false_stop_apart(420, 31)
    assert total >= 400 and hits <= allowed(total), (hits, total)


def first_case2_run_into_rest():
    """The first of ``case2_tracks(8, 23)`` whose segmentation ran sliding
    into the rest: (track, its segments, frame interval), or a test failure."""
    from cuespin.recover.paper import ran_into_rest
    from cuespin.recover.simulate import case2_tracks
    for tr in case2_tracks(8, 23):
        p = tr.params
        seg = segment_track(tr.t, tr.xy, rolling_deceleration(p.mu_r, p.g), tr.sigma, tr.exposure_s)
        s = seg if ran_into_rest(seg) else seg.unended
        if s is not None and ran_into_rest(s):
            return tr, s, float(np.median(np.diff(tr.t)))
    pytest.fail("no case-2 track ran into the rest")


def test_case2_refused_when_the_stop_is_apart_from_the_rest():
    # The paper's case 2 takes x1 = x2 only when they agree: a rest moved
    # 5 mm from where sliding stopped answers failed, never case 2's x1 = x2.
    from dataclasses import replace

    from cuespin.recover.paper import paper_from_segments
    tr, s, dt = first_case2_run_into_rest()
    p = tr.params
    kept = paper_from_segments(s, tr.t, tr.xy, p, tr.sigma, dt)
    assert kept.status != "failed" or "run into the rest" not in kept.reason
    moved = paper_from_segments(replace(s, x2=s.x2 + np.array([5e-3, 0.0])), tr.t, tr.xy, p, tr.sigma, dt)
    assert moved.status == "failed" and "did not run into the rest" in moved.reason, moved.reason


def test_case2_when_the_stop_is_within_its_errors_of_the_rest():
    # A segmentation that ends sliding just short of the rest (x1 within its
    # errors of x2, v1 not zero: not "ran into the rest") is case 2 as far
    # as the track can tell: the paper answers case 2's x1 = x2, not the
    # line's eq. 39 at x2 - x1 ~ 0 (seed 21's realistic shot 27: x1 1.8 mm
    # short, w0 6.8 stated errors off).  Apart (5 mm short), the line.
    from dataclasses import replace

    from cuespin.recover.paper import paper_from_segments, ran_into_rest
    tr, s, dt = first_case2_run_into_rest()
    p = tr.params
    case2 = paper_from_segments(s, tr.t, tr.xy, p, tr.sigma, dt)
    assert case2.status == "ok", case2.reason
    along = (s.x2 - s.x0) / np.hypot(*(s.x2 - s.x0))
    sd = float(np.sqrt(np.trace(s.geometry_cov["x1"]) / 2))
    for short, same in ((0.5 * sd, True), (5e-3, False)):
        early = replace(s, x1=s.x2 - short * along, v1=0.01 * along, t1=s.t2 - 2 * dt)
        assert not ran_into_rest(early)
        got = paper_from_segments(early, tr.t, tr.xy, p, tr.sigma, dt)
        if same:
            assert got.status == "ok" and got.stop_apart is False, got.reason
            assert np.allclose(got.v0, case2.v0, rtol=0.05) and np.allclose(got.w0, case2.w0, rtol=0.05, atol=0.1)
        else:
            assert got.stop_apart is not False and (got.status != "ok" or not np.allclose(got.w0, case2.w0, rtol=0.05))


def false_rolling_speed(n, seed):
    """Straight shots that slide, then roll to a rest in view
    (recover.simulate.rolls_to_rest_tracks) whose segmentation keeps a
    breakpoint in view, and how many of the line's case-3 answers
    (recover.paper) the rolling-speed test refuses (eq. 19)."""
    from cuespin.fit.decide import t1_in_view
    from cuespin.recover.paper import paper_from_segments, ran_into_rest
    from cuespin.recover.simulate import rolls_to_rest_tracks
    hits = total = 0
    for tr in rolls_to_rest_tracks(n, seed):
        p = tr.params
        seg = segment_track(tr.t, tr.xy, rolling_deceleration(p.mu_r, p.g), tr.sigma, tr.exposure_s)
        if not seg or seg.t2 is None or not np.isfinite(seg.t1) or ran_into_rest(seg) \
                or not t1_in_view(seg.t1, tr.t[tr.t <= seg.t2]):
            continue
        res = paper_from_segments(seg, tr.t, tr.xy, p, tr.sigma, 1.0 / tr.fps)
        if res.rolling_speed is not None:
            total += 1
            hits += res.rolling_speed.yes
    return hits, total


def test_false_rolling_speed_rate_small():
    # At the level in force (ROLL_SPEED_LEVEL, 0.081%: 0 allowed of 32; 0 read)
    from cuespin.fit.decide import ROLL_SPEED_LEVEL
    hits, total = false_rolling_speed(48, 21)
    assert total >= 25 and hits <= allowed(total, ROLL_SPEED_LEVEL), (hits, total)


@pytest.mark.slow
def test_false_rolling_speed_rate_400():
    # seed 31: held out (ROLL_SPEED_FACTOR was set on seed 2 and checked on 3);
    # at the level in force (ROLL_SPEED_LEVEL, 0.081%: 1 allowed of 447; 1 read)
    from cuespin.fit.decide import ROLL_SPEED_LEVEL
    hits, total = false_rolling_speed(640, 31)
    assert total >= 400 and hits <= allowed(total, ROLL_SPEED_LEVEL), (hits, total)


def _rest_found_early(tr, early_s: float = 0.066):
    """A case-2 track's segmentation with its rest found ``early_s`` before
    the stop (realistic H.264 36/38's 66 ms), where it answers with the
    line's case 3 (sliding ended in view, not run into the rest); else None."""
    from cuespin.fit.decide import t1_in_view
    from cuespin.recover.paper import ran_into_rest
    p = tr.params
    decel = rolling_deceleration(p.mu_r, p.g)
    seg0 = segment_track(tr.t, tr.xy, decel, tr.sigma, tr.exposure_s)
    k = int(np.searchsorted(tr.t, phases(tr.shot, p).t2 - early_s))
    seg = segment_track(tr.t, tr.xy, decel, tr.sigma, tr.exposure_s, frames=(seg0.k_move, k))
    if not seg or seg.t2 is None or not np.isfinite(seg.t1) or ran_into_rest(seg) \
            or not t1_in_view(seg.t1, tr.t[tr.t <= seg.t2]):
        return None
    return seg


def test_rolling_speed_refuses_a_slide_into_a_rest_found_early():
    # Realistic H.264 36/38's situation (docs/measurements.md, p38, v1chk):
    # a case-2 slide into the rest whose rest is found 66 ms before the
    # stop.  The segmentation ends sliding early and bridges to the rest
    # with a short "rolling" piece; x1 is apart from x2, so the line's case
    # 3 answers, at a speed that would roll far past the rest (eq. 18-19).
    # Refused at the stated level on every such answer (measured, fit.decide's
    # ROLL_SPEED_FACTOR record: 56 of 56 of seed 5's 400 tracks, z >= 5.0,
    # positive: the rest short of the rolling path; here the first 40, 4 answered
    # by the line); the segmentation's slide into the rest answers right.
    from cuespin.fit import decide
    from cuespin.fit.decide import ROLL_SPEED_LEVEL
    from cuespin.recover.paper import paper_from_segments, ran_into_rest
    from cuespin.recover.simulate import case2_tracks
    refused = total = 0
    for tr in case2_tracks(40, 5):
        p = tr.params
        seg = _rest_found_early(tr)
        if seg is None:
            continue
        dt = 1.0 / tr.fps
        got = paper_from_segments(seg, tr.t, tr.xy, p, tr.sigma, dt)
        if got.rolling_speed is None:
            continue  # case 2 by stop_apart: not the line
        total += 1
        assert got.rolling_speed.level == ROLL_SPEED_LEVEL
        if not (got.rolling_speed.yes and got.rolling_speed.statistic > 0):
            continue
        refused += 1
        assert got.status == "failed" and "eq. 18-19" in got.reason, got.reason
        if refused > 1:
            continue
        # Without the test the line's answer is many of its errors off.
        try:
            decide.ROLL_SPEED_Z, thr = float("inf"), decide.ROLL_SPEED_Z
            line = paper_from_segments(seg, tr.t, tr.xy, p, tr.sigma, dt)
        finally:
            decide.ROLL_SPEED_Z = thr
        truth = np.r_[tr.shot.v0, tr.shot.w0]
        assert line.status == "ok"
        assert np.max(np.abs(np.r_[line.v0, line.w0] - truth) / np.r_[line.stderr["v0"], line.stderr["w0"]]) > 5
        # The slide into the rest, the segmentation's other reading, answers within 3 of its errors.
        assert seg.unended is not None and ran_into_rest(seg.unended)
        case2 = paper_from_segments(seg.unended, tr.t, tr.xy, p, tr.sigma, dt)
        assert case2.status == "ok", case2.reason
        z = (np.r_[case2.v0, case2.w0] - truth) / np.r_[case2.stderr["v0"], case2.stderr["w0"]]
        assert np.max(np.abs(z)) < 3, z
    assert total >= 3 and refused == total, (refused, total)


def test_rolling_speed_asked_under_ar1_errors():
    # Realistic MJPG 49/16's situation (docs/measurements.md, papshort, seg16):
    # a slide into the rest whose rest is found early, under a lossy
    # intra-frame codec's AR(1) errors.  Before seg16 the rolling-speed test
    # was never asked under AR(1) (recover.paper.rolling_speed_asked) and
    # the line's case 3 answered `ok` far off: here case2_tracks(40, 5, rho
    # 0.3), the rest put 66 ms before the stop, 4 line answers 7-30 stated
    # errors off.  Now asked (ar1 within ROLL_SPEED_MAX_AR1_FRAMES)
    # and refused at more than twice the threshold on every one (z 6.6-33).
    from cuespin.fit.decide import ROLL_SPEED_Z
    from cuespin.recover.measurements import build_measurements
    from cuespin.recover.paper import paper_from_segments, rolling_speed_asked
    from cuespin.recover.simulate import case2_tracks
    rho = 0.3
    refused = total = 0
    for tr in case2_tracks(40, 5, rho=rho):
        p = tr.params
        dt = 1.0 / tr.fps
        assert rolling_speed_asked((rho, 1.0, None), dt)
        seg = _rest_found_early(tr)
        if seg is None:
            continue
        meas = build_measurements(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), t0=seg.t0, t_rest=seg.t2,
                                  exposure_s=tr.exposure_s, frame_dt=dt, group_rest=False)
        got = paper_from_segments(seg, tr.t, tr.xy, p, tr.sigma, dt, meas=meas, noise=(rho, 1.0))
        if got.rolling_speed is None:
            continue  # case 2 by stop_apart: not the line
        total += 1
        refused += got.status == "failed" and got.rolling_speed.statistic > 2 * ROLL_SPEED_Z
    assert total >= 4 and refused >= total - 1, (refused, total)


@pytest.mark.slow
def test_false_rolling_speed_rate_400_ar1():
    # The rolling-speed test asked under AR(1) errors (recover.paper.
    # rolling_speed_asked, ROLL_SPEED_MAX_AR1_FRAMES), through
    # recover.estimate as a lossy intra-frame codec's track: straight shots
    # rolling to a rest (rolls_to_rest_tracks), rho 0.2 and 0.3, seed 16
    # (held out: the rule's one frame was set on seeds 13-15; docs/
    # measurements.md, seg16).  Asked where the fit's ar1 allows it; refused
    # (failed, or routed to the slide into the rest) within the level's
    # binomial margin.
    from cuespin.fit.decide import ROLL_SPEED_LEVEL
    from cuespin.recover.simulate import rolls_to_rest_tracks
    hits = total = 0
    for rho in (0.2, 0.3):
        for tr in rolls_to_rest_tracks(450, 16, rho=rho):
            est = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s,
                           lossless=False, inter_frame=False)
            d = est.decisions.get("rolling_speed_differs")
            if d is None and est.paper is not None:
                d = est.paper.rolling_speed
            if d is not None:
                total += 1
                hits += bool(d.yes)
    assert total >= 400 and hits <= allowed(total, ROLL_SPEED_LEVEL), (hits, total)


def test_codec_correlation_in_place_is_the_formulas_bits():
    # _time_correlation builds its matrix in place (docs/measurements.md,
    # rec10): the same numbers, bit for bit, as the formula written out, in
    # both forms; shared_rho is that matrix with a zero diagonal, kept
    # read-only for its callers (none writes to it).
    import cuespin.recover.mle as mle

    rng = np.random.default_rng(11)
    a, b, tau, tau_long = mle.INTER_CODEC_ACF
    for t in (np.arange(1) / 60.0, np.arange(90) / 60.0, np.sort(rng.uniform(0.0, 1.5, 361))):
        dt = np.abs(t[:, None] - t[None, :])
        want = a * np.exp(-dt / tau_long) + b * np.exp(-dt / tau)
        np.fill_diagonal(want, 1.0)
        assert np.array_equal(mle._time_correlation.__wrapped__((t.tobytes(), tuple(map(float, mle.INTER_CODEC_ACF)),
                                                                None, None)), want)
        want = 0.6 ** (dt / (1 / 240))
        np.fill_diagonal(want, 1.0)
        assert np.array_equal(mle._time_correlation.__wrapped__((t.tobytes(), None, 0.6, 1 / 240)), want)
    t = np.arange(40) / 60.0
    rho = mle._shared_rho(t.tobytes(), tuple(map(float, mle.INTER_CODEC_ACF)))
    want = time_correlation(t)
    np.fill_diagonal(want, 0.0)
    assert np.array_equal(rho, want) and not rho.flags.writeable


def test_slide_through_sums_in_chunks_are_one_directions_bits():
    # slide_through_chi2's 360 directions summed SLIDE_THROUGH_CHUNK at a
    # time give each direction's sum as one vector's, bit for bit.
    import cuespin.recover.mle as mle

    rng = np.random.default_rng(12)
    for m2 in (2, 73, 720, 2001):
        rp, ex, ey = rng.standard_normal((3, m2)) * rng.uniform(0.1, 100.0, (3, 1))
        th = np.linspace(0.0, 2.0 * np.pi, 360, endpoint=False)
        one = np.array([np.sum((rp - np.cos(a) * ex - np.sin(a) * ey) ** 2) for a in th])
        assert np.array_equal(mle._through_sums(rp, ex, ey, 360), one)
