"""Found centres checked against the ball's path (track.path), and the
colour channel blind to white (track.colour.white_free), the pulled-fit rule by
phase (track.tracker.pulled_fits): pure functions."""

import numpy as np

from cuespin.track.colour import WHITE_FREE_MIN, white_free
from cuespin.track.path import PATH_TOL_RADII, off_path

R_PX = 8.0


def path_with_noise(seed=0, n=120, noise=0.05 * R_PX):
    """A ball at rest for 40 frames, struck (3 px/frame, slowing), then
    reversed by a cushion at frame 100; per-frame noise ``noise`` px."""
    rng = np.random.default_rng(seed)
    k = np.arange(n, dtype=float)
    s = np.where(k < 40, 0.0, 3.0 * (k - 40) - 0.01 * (k - 40) ** 2)
    s = np.where(k > 100, 2 * s[100] - s, s)  # the cushion sends it back
    uv = np.c_[100 + 0.8 * s, 200 + 0.6 * s] + rng.normal(0, noise, (n, 2))
    return uv, np.ones(n, bool), np.broadcast_to(noise**2 * np.eye(2), (n, 2, 2))


def test_true_path_is_kept_across_the_strike_and_a_cushion():
    uv, ok, cov = path_with_noise()
    assert not off_path(uv, ok, R_PX, cov=cov).any()


def test_isolated_and_paired_jumps_are_caught_and_their_neighbours_kept():
    # Errors 0.02 radii per axis (the tracker's: 0.001-0.005 radii on
    # realistic 12-px balls); at 0.05 the predictions' own error (PATH_SIGMAS)
    # makes a 1.2-radius jump a borderline case, as it should.
    uv, ok, cov = path_with_noise(1, noise=0.02 * R_PX)
    bad = [20, 55, 56, 80]
    uv[20] += [2.5 * R_PX, -1.0 * R_PX]       # the cue's tip while the ball rests
    uv[55:57] += [[-1.3 * R_PX, 0], [-1.2 * R_PX, 0.3 * R_PX]]  # a crescent twice
    uv[80] += [0, 1.3 * R_PX]
    ok[[30, 57]] = False                       # frames lost around them
    flagged = off_path(uv, ok, R_PX, cov=cov)
    assert set(np.flatnonzero(flagged)) == set(bad)


def test_a_false_pair_at_the_start_does_not_vouch_for_itself():
    # Review of fp4: the red ball's crescent in the first two ok frames
    # (1.37 and 1.32 radii off, the same way) passed, each through the other.
    uv, ok, cov = path_with_noise(3, noise=0.01 * R_PX)  # the tracker's errors there: 0.01-0.05 radii
    ok[:11] = False
    uv[11:13] += [[1.37 * R_PX, 0.2], [1.32 * R_PX, 0.0]]
    assert set(np.flatnonzero(off_path(uv, ok, R_PX, cov=cov))) == {11, 12}


def test_fast_strike_and_variable_frame_times_keep_true_centres():
    # 60 fps, a frame-long exposure, struck at 4.7 radii a frame (8 m/s): the
    # frame whose exposure spans the strike lies between the rest and the
    # departure; frame intervals jittered by up to 40% (vfr_jitter), each
    # centre at its own time.
    rng = np.random.default_rng(4)
    n = 80
    t = np.cumsum(rng.uniform(0.6, 1.4, n))
    t0 = t[30] - 0.5                      # the strike inside frame 30's exposure
    v = 4.7 * R_PX
    # the exposure-averaged centre over [t - 1, t]: the mean of max(0, s - t0)
    lo, hi = np.maximum(t - 1 - t0, 0), np.maximum(t - t0, 0)
    s = v * (hi**2 - lo**2) / 2
    uv = np.c_[100 + 0.8 * s, 200 + 0.6 * s] + rng.normal(0, 0.05 * R_PX, (n, 2))
    cov = np.broadcast_to((0.05 * R_PX) ** 2 * np.eye(2), (n, 2, 2))
    assert not off_path(uv, np.ones(n, bool), R_PX, t=t, cov=cov).any()


def test_noisy_track_ends_are_kept():
    # Review: at 0.1 radii of error per axis the last two frames, predicted
    # from one side only, were dropped ~10% of the time; the miss's own
    # error now widens the tolerance (PATH_SIGMAS).
    dropped = 0
    for seed in range(100):
        uv, ok, cov = path_with_noise(seed, noise=0.1 * R_PX)
        dropped += off_path(uv, ok, R_PX, cov=cov).sum()
    assert dropped <= 1, dropped  # of 12,000 true centres (measured: 0 here, 0 of 36,000 on seeds 100-399)


def test_a_centre_within_the_tolerance_is_kept():
    uv, ok, cov = path_with_noise(2, noise=0.0)
    uv[60] += [0.8 * PATH_TOL_RADII * R_PX, 0]
    assert not off_path(uv, ok, R_PX, cov=cov).any()


def test_white_free_weights_see_no_white_and_keep_the_hue():
    S = 7.8**2 * np.eye(3)
    d = np.array([-11.0, 76.0, 66.0])          # orange ball less red felt (BGR)
    w = white_free(d, S)
    assert w is not None and abs(w.sum()) < 1e-9 * np.abs(w).sum()
    kept = (w @ d) ** 2 / (w @ S @ w) / (d @ np.linalg.solve(S, d))
    assert WHITE_FREE_MIN <= kept < 1
    # A white ball on grey felt differs in brightness only: no such channel.
    assert white_free(np.array([120.0, 118.0, 121.0]), S) is None


def test_a_rest_is_held_to_its_own_typical_fit():
    # A logo fitted at rest explains its window ~3.5 times worse than the
    # blurred ball in motion: against the pooled typical fit every rest frame
    # was dropped; each phase against its own, only a fit pulled within it.
    from cuespin.track.tracker import PULLED_RMS_FACTOR, pulled_fits

    rng = np.random.default_rng(5)
    still = np.r_[np.ones(60, bool), np.zeros(100, bool)]
    rms = np.where(still, 3.5, 1.0) * rng.uniform(0.9, 1.1, len(still))
    rms[[10, 100]] *= 1.2 * PULLED_RMS_FACTOR     # one pulled fit in each phase
    ok = np.ones(len(rms), bool)
    assert pulled_fits(rms, ok)[still].sum() >= 59  # the pooled rule: the rest dropped
    assert set(np.flatnonzero(pulled_fits(rms, ok, still=still))) == {10, 100}


def test_a_look_that_spreads_the_fits_is_not_a_pull():
    # sample_scenes(6, 6, realistic, FFV1)[1]'s residuals (a dotted ball
    # rolling at 240 fps, the lit sphere): the frames whose dots the
    # markings rule did not find (at the rim) explain their window ~4 times
    # worse than the best quarter, and all were within 0.007 R; a fit held
    # 0.25 R off explains its window at least 11 times worse (pulled7).
    # Their values here: quartiles 1.98 and 4.18, those frames 7.3-8.3.
    from cuespin.track.tracker import PULLED_RMS_FACTOR, PULLED_SPREAD_IQRS, pulled_fits

    rng = np.random.default_rng(6)
    rms = rng.choice([1.6, 2.2, 3.0, 4.2], 480) * rng.uniform(0.9, 1.1, 480)
    rms[::14] = rng.uniform(7.3, 8.3, len(rms[::14]))  # the dots unfound: 35 frames
    ok = np.ones(len(rms), bool)
    q1, q3 = np.percentile(rms, [25, 75])
    assert (rms > PULLED_RMS_FACTOR * q1).sum() >= 30  # against the best quarter alone: dropped
    assert not pulled_fits(rms, ok).any()
    # A fit held 0.25 R off on those windows: RMS 22.8 or more, measured.
    rms[[7, 300]] = 22.8
    assert q3 + PULLED_SPREAD_IQRS * (q3 - q1) < 22.8
    assert set(np.flatnonzero(pulled_fits(rms, ok))) == {7, 300}


def test_a_run_of_pulled_fits_is_dropped_whatever_its_share():
    # False centres come in runs (the cue's tip over several frames): a run
    # over a quarter of the fits must not set the fence that judges it
    # (review 10a: with the quartiles over every fit, runs of 26-50% were
    # all kept).  Runs of 4x the typical RMS, the rest within +-10%.
    from cuespin.track.tracker import pulled_fits

    rng = np.random.default_rng(7)
    for n, share in [(200, 0.24), (200, 0.26), (200, 0.5), (12, 0.25), (40, 0.25)]:
        rms = rng.uniform(0.9, 1.1, n)
        run = np.arange(n) < round(share * n)
        rms[run] *= 4.0
        assert np.array_equal(pulled_fits(rms, np.ones(n, bool)), run), (n, share)


def test_an_ill_determined_centre_that_fits_worse_is_a_pull():
    # sample_scenes(6, 7, realistic, FFV1)[5] (red on red in a low light),
    # its 32 fits as recorded (rms in levels, the stated error's larger axis
    # in px, their error in radii): frames 33, 56 and 59 are 0.25-0.31 R off,
    # fitted only 1.26-1.65 times worse than the reference (the RMS rule
    # needs 3) but stating 5-9 times the track's median error (red8).
    from cuespin.track.tracker import ILL_RMS_FACTOR, ILL_SE_FACTOR, pulled_fits

    frames = np.array([14, 15, 17, 18, 19, 20, 21, 24, 25, 26, 27, 28, 33, 34, 35, 37, 39, 41, 44, 47, 48, 51, 52, 54,
                       55, 56, 59, 61, 63, 64, 76, 78])
    rms = np.array([13.77, 1.67, 1.81, 1.87, 1.81, 1.6, 2.2, 1.81, 1.83, 1.75, 1.72, 1.81, 2.26, 2.28, 2.29, 1.81, 1.79,
                    1.67, 1.77, 2.3, 2.23, 2.32, 3.33, 3.37, 3.09, 2.97, 2.45, 2.59, 2.73, 2.07, 1.76, 1.86])
    se = np.array([0.194, 0.095, 0.092, 0.008, 0.011, 0.048, 0.011, 0.089, 0.013, 0.018, 0.043, 0.02, 0.233, 0.012,
                   0.011, 0.055, 0.029, 0.052, 0.065, 0.011, 0.012, 0.013, 0.013, 0.051, 0.028, 0.327, 0.246, 0.243,
                   0.012, 0.023, 0.076, 0.046])
    err = np.array([0.464, 0.001, 0.002, 0.001, 0.002, 0.012, 0.002, 0.012, 0.001, 0.001, 0.009, 0.001, 0.251, 0.003,
                    0.001, 0.089, 0.003, 0.007, 0.003, 0.003, 0.002, 0.001, 0.003, 0.006, 0.005, 0.309, 0.28, 0.163,
                    0.002, 0.001, 0.068, 0.06])
    still = np.isin(frames, [63, 64])
    ok = np.ones(len(rms), bool)
    assert set(frames[pulled_fits(rms, ok, still=still)]) == {14}  # the RMS rule alone
    pulled = pulled_fits(rms, ok, still=still, se=se)
    assert set(frames[err > 0.25]) <= set(frames[pulled])
    assert (err[pulled] > 0.15).all()  # 61 (0.163 R) the one correct fit dropped of 13610 measured
    # A correct fit stating far more than the track's typical error (a
    # streak's length; 500 times in sample_scenes(6, 5, realistic, FFV1)[2])
    # and fitted as the others are: kept.  Measured, such fits reach 1.07
    # times the reference, under ILL_RMS_FACTOR.
    se2 = se.copy()
    se2[3] = 500 * ILL_SE_FACTOR * np.median(se)
    rms2 = rms.copy()
    rms2[3] = 1.07 * np.percentile(rms[~still], 25)
    assert not pulled_fits(rms2, ok, still=still, se=se2)[3]
    assert ILL_RMS_FACTOR > 1.07
