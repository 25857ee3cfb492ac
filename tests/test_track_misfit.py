"""The track's own measure of what the ball's model misses (track.misfit).

Fast: simulated tracks (a struck ball sliding, then rolling: kinks at the
strike and at the end of sliding) with independent errors as stated must
keep their errors (factor 1), and with an added AR(1) error the factor must
find its variance.  Slow: realistic renders (shading, highlights, markings
turning with the spin) whose per-frame errors the fits may understate
(1.4 times on a logo's track) must come out honest: err/se within issue
10's 0.8-1.25; and a disc on H.264 (2.8 times) too.
"""

import numpy as np
import pandas as pd
import pytest

from cuespin.track.misfit import look_misfit

PX_PER_M = 470.0  # the realistic look's framing of a 9-ft table in 1280 px


def simulated(rng, fps, seconds, se, excess=0.0, rho=0.0, t0=0.1, t1=0.3, t=None):
    """A struck ball's centres (px), stated covariances and ok flags: at
    rest until ``t0``, sliding (2.9 m/s^2) until ``t1``, then rolling; each
    centre with independent errors ``se`` (px), plus an AR(1) error of
    variance ``excess`` se^2 and lag-1 correlation ``rho``; frames at ``t``
    (s; default ``k / fps``)."""
    if t is None:
        t = np.arange(int(seconds * fps)) / fps
    v0, a_s, a_r = np.array([1.5, 0.4]), np.array([-2.5, 1.5]), np.array([-0.07, -0.02])
    d = np.clip(t - t0, 0, t1 - t0)[:, None]
    x = v0 * d + 0.5 * a_s * d * d
    r = np.clip(t - t1, 0, None)[:, None]
    x += (v0 + a_s * (t1 - t0)) * r + 0.5 * a_r * r * r
    e = rng.normal(0.0, se, x.shape)
    if excess > 0:
        a = np.zeros_like(e)
        a[0] = rng.normal(0, 1, 2)
        for k in range(1, len(a)):
            a[k] = rho * a[k - 1] + np.sqrt(1 - rho**2) * rng.normal(0, 1, 2)
        e += np.sqrt(excess) * se * a
    cov = np.broadcast_to(np.eye(2) * se**2, (len(t), 2, 2)).copy()
    return 100 + PX_PER_M * x + e, cov, np.ones(len(t), bool)


@pytest.mark.parametrize("fps", [60, 240, 480])
def test_independent_errors_keep_their_stated_size(fps):
    # Measured: 0-2% of such tracks inflated at 0.05 px (the test's 3.09-sigma
    # threshold), none by more than 1.9x.
    rng = np.random.default_rng(fps)
    f = np.array([look_misfit(*simulated(rng, fps, 1.0, 0.05)).factor for _ in range(40)])
    assert np.mean(f > 1) <= 0.1 and f.max() < 2.5, f


@pytest.mark.parametrize("excess, rho", [(3.0, 0.0), (3.0, 0.5), (5.0, 0.8)])
def test_a_correlated_misfit_is_found(excess, rho):
    # Measured at 300 frames: median factor within 3% of the truth, p10-p90
    # within 25% (rho 0.8: 4.2-8.3 for 6).
    rng = np.random.default_rng(int(10 * excess + 100 * rho))
    res = [look_misfit(*simulated(rng, 480, 0.75, 0.05, excess, rho)) for _ in range(25)]
    f = np.array([r.factor for r in res])
    assert abs(np.median(f) / (1 + excess) - 1) < 0.2, f
    assert abs(np.median([r.rho for r in res]) - rho) < 0.25  # measured: 0.2 when rho is 0


def test_a_misfit_is_measured_with_frames_lost():
    # Review: lost frames were taken for still ones, and the strike's edge
    # erosion around each cost ~5 moving frames.  Measured (120 fps, 2 s,
    # 10% of frames lost at random, true factor 4, lag-1 0.5; 60 tracks):
    # median factor 3.91 (2.53 before), p10 2.16; found on every track.
    rng = np.random.default_rng(125)
    f = []
    for _ in range(30):
        uv, cov, ok = simulated(rng, 120, 2.0, 0.05, 3.0, 0.5)
        f.append(look_misfit(uv, cov, ok & (rng.random(len(ok)) > 0.1)).factor)
    assert np.mean(np.array(f) > 1) >= 0.9 and abs(np.median(f) / 4.0 - 1) < 0.2, f


@pytest.mark.slow
def test_realistic_renders_state_honest_errors(tmp_path):
    """Three realistic FFV1 renders (dots turning at 480 fps, a logo at 240
    fps, a shaded ball at 240 fps): the stated errors, scaled by each
    track's factor, within issue 10's 0.8-1.25 of the real ones over their
    moving frames, pooled and on each track.  Measured (docs/measurements.md,
    offv; c299b31): err/se 1.08, 0.90, 1.01, pooled 1.03; before the factor
    1.31, 1.41 (factor 2.42), 1.01 (factor 1), pooled 1.25 -- the per-frame
    fits state far closer to the truth than when the test was written (2.35,
    1.50, 2.09), and misfit6's constant 0.20-0.32 px offset is gone (mean
    error along the image's v 0.008, 0.005, -0.005 px, along the motion
    0.000, -0.007, -0.002), so the factor is needed on the logo's track
    only."""
    from cuespin.data_gen.sampler import sample_scenes
    from cuespin.render import render_video
    from cuespin.track.tracker import TrackerConfig
    from cuespin.track.video import track_video

    zs, rms, raw = [], [], []
    for seed, i in ((5, 0), (8, 1), (8, 6)):
        scene = sample_scenes(i + 1, seed, look="realistic", codec="FFV1")[i]
        scene.render["max_duration"] = 0.7
        path = tmp_path / f"s{seed}_{i}.avi"
        render_video(scene, path)
        tr = track_video(path, scene, TrackerConfig(threaded=False))
        truth = pd.read_csv(path.with_suffix(".truth.csv"))
        n = min(tr.n_frames, len(truth))
        err = tr.uv[:n] - np.c_[truth.uc_px, truth.vc_px][:n]
        moving = tr.ok[:n] & (tr.t[:n] > scene.truth.t0 + 0.02)
        z = err[moving] / tr.stderr_px[:n][moving]
        zs.append(z)
        rms.append(np.sqrt(np.mean(z**2)))
        raw.append(rms[-1] * np.sqrt(tr.look_factor))
    pooled = np.sqrt(np.mean(np.concatenate(zs) ** 2))
    assert 0.8 <= pooled <= 1.25 and all(0.8 <= r <= 1.25 for r in rms), (pooled, rms)
    assert max(raw) > 1.25, raw  # one track's per-frame fits alone understate it (the logo's, 1.41)


@pytest.mark.parametrize("fps", [60, 120, 240])
def test_a_variable_frame_rate_is_not_a_misfit(fps):
    # Intervals jittered by up to 3% (render.vfr_jitter 0.03): a ball at
    # 1.5 m/s moves 0.07-0.3 px more or less between frames than at k / fps,
    # 1.4-6 times the 0.05-px errors.  With the frame times the third
    # differences are divided differences, free of the motion again: the
    # constant rate's rate of inflated factors (0-2%, above; at most 0.1 of
    # tracks here), while with k / fps's weights every track is inflated
    # (measured: by 2.8-11, median 3.6 at 240 fps to 11 at 60).
    from cuespin.track.misfit import third_difference_weights

    rng = np.random.default_rng(fps + 7)
    n = fps
    t = np.r_[0.0, np.cumsum((1 + 0.03 * rng.uniform(-1, 1, n - 1)) / fps)]
    assert np.allclose(third_difference_weights(np.arange(n) / fps, np.arange(3, 10), 3), [-1, 3, -3, 1])
    k = np.arange(2, n - 4)
    quad = 1.0 + 2.0 * t - 5.0 * t**2
    idx = np.stack([k - 2, k, k + 2, k + 4], axis=1)
    assert np.abs(np.sum(third_difference_weights(t, k, 2) * quad[idx], axis=1)).max() < 1e-12
    with_t = [look_misfit(*simulated(rng, fps, 1.0, 0.05, t=t), t=t).factor for _ in range(20)]
    without = [look_misfit(*simulated(rng, fps, 1.0, 0.05, t=t)).factor for _ in range(20)]
    assert np.mean(np.array(with_t) > 1) <= 0.1 and max(with_t) < 2.5, with_t
    assert min(without) > 2.0, without


@pytest.mark.slow
def test_a_variable_rate_h264_track_keeps_the_constant_rates_factor(tmp_path):
    """benchmarks/vfr.py's shot 6 (H.264 CRF 20, 120 fps, noise 3, 250 px/m):
    rendered at a constant rate and with intervals jittered by 3%, the same
    noise.  Written when its fits took the shaded look: factor 3.50 (lag-1
    0.26) at the constant rate; at the variable one 11.3 (0.77) with k /
    fps's weights, 4.01 (0.35) with the frame times; err/se 1.26, 1.30.
    Since the renderer's compiled noise (37d826a) its look vote keeps the
    disc, whose errors went out unscaled, 2.8 times too small (z 2.81,
    2.71; misfit6); the misfit now runs on any look on a lossy codec
    (offv, c299b31): factor 4.27 (0.23) and 3.96 (0.14), err/se 1.36,
    1.36, the per-frame errors 0.051 px RMS."""
    import dataclasses

    from cuespin.data_gen.sampler import sample_scene
    from cuespin.render import render_video
    from cuespin.track.video import track_video

    scene = sample_scene(161576974, "case3", fps=120.0, px_per_m=250.0, noise=3.0, blur=False, codec="H264")
    factors, z = {}, {}
    for j in (0.0, 0.03):
        sc = dataclasses.replace(scene, render={**scene.render, "max_duration": 3.0, "vfr_jitter": j})
        path = tmp_path / f"v{j}.mp4"
        render_video(sc, path)
        tr = track_video(path, sc)
        truth = pd.read_csv(path.with_suffix(".truth.csv"))
        n = min(tr.n_frames, len(truth))
        assert np.abs(tr.t[:n] - truth.t.values[:n]).max() < 1e-12        # the file's times, read back
        tuv = np.c_[truth.uc_px, truth.vc_px][:n]
        moving = tr.ok[:n] & (np.r_[0, np.hypot(*np.diff(tuv, axis=0).T)] > 0.3)
        z[j] = np.sqrt(np.mean(((tr.uv[:n] - tuv)[moving] / tr.stderr_px[:n][moving]) ** 2))
        factors[j] = tr.look_factor
    assert factors[0.03] / factors[0.0] < 1.6, factors          # measured 0.93 (1.15 shaded); 3.2 before
    assert 0.8 < z[0.03] < 1.5 and abs(z[0.03] / z[0.0] - 1) < 0.2, z


def _null_false_positives(tracks, px_per_m=500.0):
    """How many of ``tracks`` (recover.simulate.SimTrack: independent errors
    stated right) the look misfit inflates, fed as track.video feeds it
    (centres and covariances at a px scale, every frame ok), and the count."""
    fired = n = 0
    for tr in tracks:
        se = tr.sigma * px_per_m
        cov = np.broadcast_to(np.eye(2) * se * se, (len(tr.t), 2, 2))
        fired += look_misfit(tr.xy * px_per_m, cov, np.ones(len(tr.t), bool)).factor > 1
        n += 1
    return fired, n


def _allowed(n, rate=0.001):
    """The nominal rate plus two binomial standard errors, as a count."""
    return int(np.floor(n * (rate + 2 * np.sqrt(rate * (1 - rate) / n))))


def test_excess_z_false_positive_rate_on_rolling_null_tracks():
    # EXCESS_Z's nominal rate (one-sided 0.1%) on 400 tracks rolling from the
    # strike (recover.simulate, 60-480 fps, 0.01-0.3 px at 500 px/m,
    # exposures 0.3-1 frame half the time): no kink but the stop.  Measured
    # (2026-11-30, seeds 1 and 2 of mixed_tracks): 4 of 6000, 0.07%.
    from cuespin.recover.simulate import null_rolling_tracks

    fired, n = _null_false_positives(null_rolling_tracks(400, 11))
    assert n == 400 and fired <= _allowed(n), fired


@pytest.mark.slow
def test_excess_z_false_positive_rate_on_sliding_null_tracks():
    # Before the kink was taken out (seeds 1 and 2, 6000 sliding tracks):
    # 267 inflated (4.45%; 60-240 fps 1-10%, 480 fps 0-0.4%), factors
    # p10/50/90 1.9/2.7/6.0: the last still frame before the strike passed
    # for moving, and the end of sliding spoiled 2 of the longest spacing's
    # 5-6 blocks.  With the frames next to a still one left out and the
    # end of sliding fitted out (track.misfit.remove_kink): 0 of 400 here
    # (23 before), see EXCESS_Z for the larger runs.
    from cuespin.recover.simulate import sliding_tracks

    fired, n = _null_false_positives(sliding_tracks(400, 12))
    assert fired <= _allowed(n), fired

