"""The tracker on the project's own rendered videos: accuracy against the
Cramer-Rao bound, background modelling, flags, and bad input."""

import json
import subprocess
import sys

import numpy as np
import pytest

from cuespin.data_gen.sampler import make_scene, sample_scene, sample_shot
from cuespin.physics import Shot
from cuespin.pipeline.io import write_scene
from cuespin.render import FrameRenderer, render_video
from cuespin.render.video import encode_frames
from cuespin.pipeline.measure import tracker_accuracy
from cuespin.track.tracker import GONE, PARTIAL, TWO_BLOBS
from cuespin.track.video import read_track_csv, track_video, write_track_csv

# The accuracy requirement: RMSE within 1.5x of the bound on lossless
# video.  Measured here (benchmarks/track.py): 1.0-1.3x for the disc fit.
CRB_RATIO_MAX = 1.5
# Grey-weighted moments measured at 2.0-2.6x the bound: the fit must beat them.
MOMENTS_RATIO_MIN = 1.7
# Every frame's metres within this many (bound x allowed ratio) of the truth:
# the largest of ~150 Gaussian errors per axis is about 3 sigma.
XY_SIGMAS = 5.0
# RMS of the errors in the tracker's stated errors (benchmarks/track.py
# accuracy, err/se): 0.90-1.08 over noise 0.08-10 on sharp FFV1 video; the
# pooled-RMS errors it replaced measured 3.6 at noise 0.08.
STATED_Z_RANGE = (0.75, 1.3)


def run_condition(tmp_path, scene, refine="fit"):
    """Render, track; RMSE and bound over frames where the ball moves."""
    acc = tracker_accuracy(scene, tmp_path / "v.avi", refine)
    return acc.result, acc.truth, acc.rmse, acc.crb


def short_scene(seed=5, preset="case3", fps=240.0, noise=5.0, blur=False, px_per_m=500.0,
                duration=0.7, **render):
    shot, params = sample_shot(seed, preset)
    shot = Shot(shot.x0, shot.v0, shot.w0, t0=0.15)
    exposure = 1.0 / fps if blur else 0.0
    rs = {"noise_sigma": noise, "codec": "FFV1", "duration": duration, "seed": seed,
          "felt_grey": 90.0, "ball_grey": 210.0}
    rs.update(render)
    return make_scene(shot, params, fps=fps, px_per_m=px_per_m, exposure_s=exposure, render=rs)


@pytest.mark.parametrize("blur,gradient", [(False, 0.0), (True, 15.0)])
def test_fit_reaches_the_bound(tmp_path, blur, gradient):
    scene = short_scene(blur=blur, gradient=gradient, gradient_angle=0.7)
    res, truth, rmse, crb = run_condition(tmp_path, scene)
    assert res.ok[truth.t > scene.truth.t0].all()
    assert rmse < CRB_RATIO_MAX * crb, (rmse, crb)
    # The reported per-frame error agrees with what was measured (within 30%).
    assert res.centroid_noise_px == pytest.approx(rmse, rel=0.3)
    # Metres through the inverse homography, stamped k / fps.
    np.testing.assert_allclose(res.t, np.arange(res.n_frames) / scene.camera.fps)
    if not blur:
        ok = res.ok
        np.testing.assert_allclose(res.xy[ok], truth.xy[ok], atol=XY_SIGMAS * CRB_RATIO_MAX * crb / 500.0)


@pytest.mark.parametrize("noise", [0.08, 5.0])
def test_stated_errors_are_honest(tmp_path, noise):
    # At noise 0.08 the 8-bit rounding, on the ball's edge only, is most of
    # the noise: one RMS pooled over the patch understated the error 3.6x.
    acc = tracker_accuracy(short_scene(noise=noise), tmp_path / "v.avi")
    assert STATED_Z_RANGE[0] < acc.stated_z < STATED_Z_RANGE[1], acc.stated_z


@pytest.mark.parametrize("travel_m", [0.05, 0.025])
def test_shot_stopping_within_a_diameter_of_its_strike(tmp_path, travel_m):
    # Natural roll over 50 mm (0.9 ball diameters): the rests and the path
    # between cover a lens of felt in every frame.  Taking the ball seen
    # there for felt pulled both rests' centres 0.03 px (ten stated errors)
    # towards each other; filled from the felt around it, the rests measured
    # within 0.2 stated errors on average.  Over 25 mm (less than a radius)
    # the learnt felt held a whole ball: the tracker lost the ball at both
    # rests (24 of 161 frames found) and the frames it found were biased.
    from cuespin.physics import BallParams, phases
    params = BallParams(mu_r=0.015)
    speed = np.sqrt(2 * 5.0 / 7.0 * params.mu_r * params.g * travel_m)
    shot = Shot((0.8, 0.6), (speed, 0.0), (0.0, speed / params.R), t0=0.25)
    t2 = phases(shot, params).t2
    scene = make_scene(shot, params, fps=120.0,
                       render={"noise_sigma": 1.0, "codec": "FFV1", "duration": t2 + 0.4,
                               "felt_grey": 90.0, "ball_grey": 210.0})
    video = tmp_path / "v.avi"
    truth = render_video(scene, video)
    res = track_video(video, scene)
    assert res.ok.all()
    for rest in (truth.t < shot.t0 - 0.01, truth.t > t2 + 0.01):
        bias = np.mean(res.uv[rest] - truth.uv[rest], axis=0)
        se = np.median(res.stderr_px[rest], axis=0)
        # The mean of n rest frames: its own error is se / sqrt(n); 3 se is
        # far outside it and far inside the 10 se the bug gave.
        assert np.all(np.abs(bias) < 3 * se / np.sqrt(rest.sum()) + 0.3 * se), (bias, se)


def test_moments_worse_than_fit(tmp_path):
    scene = short_scene()
    _, _, rmse_m, crb = run_condition(tmp_path, scene, refine="moments")
    assert rmse_m > MOMENTS_RATIO_MIN * crb


def test_late_strike_and_textured_felt(tmp_path):
    # The ball rests at x0 for most of the video: a plain median keeps it there.
    shot, params = sample_shot(3, "case3")
    scene = make_scene(Shot(shot.x0, shot.v0, shot.w0, t0=1.2), params, fps=120.0,
                       render={"noise_sigma": 4.0, "texture": 6.0, "codec": "FFV1",
                               "duration": 1.6, "felt_grey": 100.0, "ball_grey": 200.0})
    res, truth, rmse, crb = run_condition(tmp_path, scene)
    assert res.ok.all()
    assert rmse < CRB_RATIO_MAX * crb, (rmse, crb)


def test_slow_shot_that_stops_early(tmp_path):
    # Natural roll at 0.4 m/s on slow cloth: stops after ~2.9 s and rests at
    # x2 for the remaining ~57% of the video, where a plain median fails.
    from cuespin.physics import BallParams
    params = BallParams(mu_r=0.02)
    v0 = np.array([0.4, 0.0])
    shot = Shot((0.8, 0.6), v0, (0.0, 0.4 / params.R), t0=0.2)
    scene = make_scene(shot, params, fps=60.0,
                       render={"noise_sigma": 3.0, "codec": "FFV1", "duration": 7.0})
    res, truth, rmse, crb = run_condition(tmp_path, scene)
    assert res.ok.all()
    assert rmse < CRB_RATIO_MAX * crb, (rmse, crb)


@pytest.mark.slow
@pytest.mark.parametrize("radius_px", [8.0, 20.0])
@pytest.mark.parametrize("noise", [1.0, 10.0])
def test_bound_across_radius_and_noise(tmp_path, radius_px, noise):
    scene = short_scene(noise=noise, px_per_m=radius_px / 0.028575, duration=0.5)
    res, truth, rmse, crb = run_condition(tmp_path, scene)
    assert rmse < CRB_RATIO_MAX * crb, (rmse, crb)


def test_decoding_thread_and_single_thread_give_the_same_track(tmp_path):
    # With a lossless codec the threaded reader takes background samples from
    # its decode buffer, the single-threaded one seeks for them: the same
    # frames, so the same background and the same track, to rounding.
    from cuespin.track.tracker import TrackerConfig
    scene = short_scene(seed=8, noise=3.0, duration=1.2)
    video = tmp_path / "v.avi"
    render_video(scene, video)
    a = track_video(video, scene, TrackerConfig(threaded=True))
    b = track_video(video, scene, TrackerConfig(threaded=False))
    np.testing.assert_array_equal(a.background.image, b.background.image)
    np.testing.assert_array_equal(a.ok, b.ok)
    np.testing.assert_allclose(a.uv[a.ok], b.uv[b.ok], atol=1e-9)


def test_lossy_codec_still_tracks(tmp_path):
    scene = short_scene(codec="MJPG")
    res, truth, rmse, crb = run_condition(tmp_path, scene)
    assert res.ok[truth.t > scene.truth.t0].all()
    # MJPG at OpenCV's default quality, measured at sigma 5 (benchmarks/track.py):
    # 1.09-1.28x the lossless bound; allow 3x.
    assert rmse < 3.0 * crb


def test_ball_leaving_the_frame_ends_the_track(tmp_path):
    scene = sample_scene(4, "leaves_table", fps=120.0, noise=3.0, blur=False, codec="FFV1")
    res, truth, _, _ = run_condition(tmp_path, scene)
    # Once the disc crosses the frame's edge, no frame is ok again.
    u, v, r = truth.uv[:, 0], truth.uv[:, 1], res.radius_px
    inside = (u - r > 0) & (v - r > 0) & (u + r < scene.camera.width - 1) & (v + r < scene.camera.height - 1)
    first_out = np.argmin(inside)
    assert res.ok[:first_out - 1].all()
    assert not res.ok[first_out:].any()
    assert set(res.status[first_out:]) <= {PARTIAL, GONE}


def test_two_balls_are_flagged(tmp_path):
    scene = short_scene(duration=0.4, noise=3.0)
    r = FrameRenderer(scene)
    frames = list(r.frames())
    from cuespin.render.draw import disc_coverage
    cov = disc_coverage(200.5, 200.5, r.radius_px, 180, 180, 41, 41)
    for f in frames[:10]:  # a second ball sits there in the first 10 frames
        patch = f[180:221, 180:221].astype(float)
        f[180:221, 180:221] = np.clip(patch + 120 * cov, 0, 255).astype(np.uint8)
    video = tmp_path / "two.avi"
    encode_frames(iter(frames), video, "FFV1", scene.camera.fps, (scene.camera.width, scene.camera.height))
    res = track_video(video, scene)
    assert (res.status[:10] == TWO_BLOBS).all()
    assert res.ok[12:].all()


def test_track_csv_round_trip(tmp_path):
    scene = short_scene(duration=0.3)
    render_video(scene, tmp_path / "v.avi")
    res = track_video(tmp_path / "v.avi", scene)
    write_track_csv(tmp_path / "t.csv", res)
    back = read_track_csv(tmp_path / "t.csv")
    assert list(back) == ["frame", "t", "u_px", "v_px", "x_m", "y_m", "ok"]
    np.testing.assert_array_equal(back["ok"].astype(bool), res.ok)
    np.testing.assert_allclose(back["x_m"][res.ok], res.xy[res.ok, 0], rtol=1e-15)


def cli(*args):
    return subprocess.run([sys.executable, "-m", "cuespin.pipeline.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def one_line(res, needle):
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], res.stderr


def test_track_cli_and_bad_input(tmp_path):
    scene = short_scene(duration=0.5, codec="MJPG")
    sf = tmp_path / "s.json"
    write_scene(sf, scene)
    video = tmp_path / "v.avi"
    render_video(scene, video)
    out = tmp_path / "t.csv"
    res = cli("track", video, "--scene", sf, "-o", out)
    assert res.returncode == 0, res.stderr
    assert len(out.read_text().splitlines()) == 1 + int(0.5 * 240)
    one_line(cli("track", tmp_path / "none.avi", "--scene", sf, "-o", out), "video not found")
    (tmp_path / "junk.avi").write_bytes(b"not a video at all" * 100)
    one_line(cli("track", tmp_path / "junk.avi", "--scene", sf, "-o", out), "not a video OpenCV or PyAV can read")
    d = json.loads(sf.read_text())
    d["camera"]["width"] = 640
    (tmp_path / "wrong.json").write_text(json.dumps(d))
    one_line(cli("track", video, "--scene", tmp_path / "wrong.json", "-o", out), "but the scene's camera says")
    # A truncated file: one line, exit 2, and the frames before the cut are written.
    data = video.read_bytes()
    (tmp_path / "cut.avi").write_bytes(data[: len(data) * 2 // 3])
    res = cli("track", tmp_path / "cut.avi", "--scene", sf, "-o", tmp_path / "cut.csv")
    one_line(res, "truncated or corrupt")
    rows = read_track_csv(tmp_path / "cut.csv")
    assert 40 < len(rows["frame"]) < 120 and rows["ok"].sum() > 30


def test_no_ball_anywhere(tmp_path):
    shot, params = sample_shot(1, "case3")
    scene = make_scene(Shot(shot.x0, (0, 0), (0, 0), t0=0.1), params, fps=60.0,
                       render={"duration": 0.5, "codec": "FFV1", "noise_sigma": 2.0})
    sf = tmp_path / "s.json"
    write_scene(sf, scene)
    render_video(scene, tmp_path / "v.avi")
    one_line(cli("track", tmp_path / "v.avi", "--scene", sf, "-o", tmp_path / "t.csv"), "no ball found")


def test_felt_accumulator_sums_whole_frames_exactly():
    """The whole frames' 16-bit sums, carried into float32 every FULL_CARRY
    frames, give the float32 running sum's felt bit for bit (cv2.accumulate,
    the ball's pixels taken back out), across two carries."""
    import cv2

    from cuespin.track.background import FULL_CARRY, FeltAccumulator
    from cuespin.track.colour import Projection

    rng = np.random.default_rng(3)
    n, shape = 2 * FULL_CARRY + 9, (48, 64, 3)
    felt = FeltAccumulator(shape)
    ref = np.zeros(shape, np.float32)
    hidden = np.zeros(shape[:2], np.int32)
    for k in range(n):
        frame = rng.integers(0, 256, shape, dtype=np.uint8)
        if k <= FULL_CARRY or k % 3 == 0:
            # The sum's worst case, every frame up to the first carry: a
            # carry one frame late (258 frames of 255) wraps 16 bits.
            frame[:] = 255
        # The ball in the left half only: the right half is never hidden,
        # so its sums are the worst case's.
        centre = rng.uniform((0.0, 0.0), (30.0, 48.0))
        felt.add_frame(frame, centre, 6.0)
        cv2.accumulate(frame, ref)
        out = FeltAccumulator._disc(0, 0, 48, 64, centre, 6.0)
        ref[out] -= frame[out]
        hidden += out
    assert felt.n_full == n
    fallback = np.zeros(shape[:2], np.float32)
    green = Projection(w=np.array([0.0, 1.0, 0.0], np.float32))
    grey = felt.felt(fallback, green)
    full_count = n - hidden
    want = np.where(full_count >= 20, ref[..., 1] / np.maximum(full_count, 1), fallback)
    assert np.array_equal(felt.full, ref)
    assert np.array_equal(grey, want.astype(np.float32))


def test_contrast_of_a_shaded_ball_is_its_middles():
    # A ball brighter than the felt in its middle and darker at its wider
    # rim (the projected look of a red ball on red felt on H.264,
    # sample_scene(14, realistic)): the rim's pixels are strong but lie on
    # the felt's other side.  Counted with the middle's, the contrast read
    # 6 where the middle departs by ~125; the detection threshold, a quarter
    # of it, let a pocket through as the ball, 545 px off.
    from cuespin.track.background import learn_background

    rng = np.random.default_rng(14)
    n, H, W, r, middle, rim = 9, 80, 440, 10.0, 120.0, -30.0
    vv, uu = np.mgrid[0:H, 0:W]
    texture = rng.normal(100.0, 1.0, (H, W))
    samples = []
    for k in range(n):
        d = np.hypot(uu - (40.0 + 45.0 * k), vv - 40.0)
        ball = np.where(d < 0.5 * r, middle, np.where(d < r, rim, 0.0))
        samples.append(texture + ball + rng.normal(0.0, 0.5, (H, W)))
    bg = learn_background(np.clip(np.rint(samples), 0, 255).astype(np.uint8), r)
    assert bg.polarity == 1
    # The middle's departure, less the texture's and the rim's blur at the
    # middle's edge: measured 120.0 here, 2.0 when the rim's pixels counted.
    assert bg.contrast > 0.5 * middle, bg.contrast
    # The detection threshold is a fraction of the ball's own search score in
    # the samples, not of the contrast: this ball's box (its middle and most
    # of its dark rim) scores 27.8 against a contrast of 121, under a quarter
    # of it (the former threshold, 30.2: this failed), so the search missed
    # it; the felt's texture (0.18) must stay well under the threshold (8.3).
    from cuespin.track.tracker import BallTracker

    trk = BallTracker(bg, r, 0.0)
    frame = samples[4].astype(np.float32)
    sm = trk._score(bg.polarity * (frame - bg.image))
    d = np.hypot(uu - (40.0 + 45.0 * 4), vv - 40.0)
    peak, felt = sm[d < r].max(), np.abs(sm[d > 3 * r]).max()
    assert bg.score == pytest.approx(peak, rel=0.1), (bg.score, peak)
    assert 3 * felt < trk.thresh < 0.5 * peak, (felt, trk.thresh, peak)


def test_streak_fallback_keeps_the_strike_and_refuses_a_streak_across_the_rest_spot():
    # Where the sharp fit fails the tracker fits the moments' streak (the
    # strike).  A ball struck from rest streaks away from its rest spot; a
    # streak across it is a resting ball's whose sharp fit did not converge
    # (realistic seed 0 shot 4, FFV1, frame 90 at MAX_ITER 64: fitted as a
    # 6 px streak 2.2 px off the resting ball).
    from dataclasses import replace

    from cuespin.track.model import blur_nodes, fit_disc, streak_from_moments, streak_model
    from cuespin.track.tracker import BallTracker

    rng = np.random.default_rng(7)
    r, u0, v0, n = 7.5, 100, 200, 41
    felt = 90.0 + rng.normal(0, 2, (n, n))
    rest = np.array([117.2, 216.6])
    b = 8.0 * np.array([0.8, 0.6])
    c = rest + 0.5 * b  # the exposure opens as the ball leaves its rest spot
    img = felt + streak_model(c, b, 200.0, felt, r, u0, v0, blur_nodes(8.0))[0] + rng.normal(0, 5, (n, n))
    f = fit_disc(img, felt, u0, v0, c + [0.5, -0.4], r, 180.0, b0=streak_from_moments(img - felt, u0, v0, c, r),
                 fit_blur=True)
    assert f and np.hypot(*(f.c - c)) < 0.1 * r
    leaves = BallTracker._streak_leaves
    assert leaves(f, rest, np.zeros(2)) and leaves(replace(f, b=-f.b), rest, np.zeros(2))
    # The same streak predicted to rest at its middle: refused.
    assert not leaves(f, f.c, np.zeros(2)) and not leaves(f, f.c + 0.3 * f.b, np.zeros(2))
    # Where a streak was predicted (a ball rolling), half of it is allowed.
    assert leaves(f, f.c, f.b)
    # A streak under FIT_BLUR_PX is no streak (a sharp ball's fit): kept.
    assert leaves(replace(f, b=0.3 * f.b), f.c, np.zeros(2))


def test_a_stretch_of_cue_beyond_the_felts_still_cue_is_a_stick():
    # The cue clip's geometry (seed 6 shot 0, r = 7.8 px, foreign threshold
    # 32): the felt holds the cue where it is held after the strike, so at
    # address only the stretch reaching beyond it departs (1.9 radii long,
    # 0.45 wide), ending inside the ball's window.  Joined to the felt's
    # still cue it runs through the window: a stick.  A ball with that still
    # cue at its rear stays a ball.
    from cuespin.track.tracker import STICK_GAP_PX, stick_through

    r, thresh = 7.8, 32.0
    n = 2 * int(np.ceil(r + STICK_GAP_PX)) + 1
    c = np.array([n // 2, n // 2], float)
    felt = np.full((n, n), 100.0, np.float32)  # times the ball's polarity
    felt[11:14, 20:] += 50.0  # the still cue, from the stretch's end to the window's border
    stretch = np.zeros((n, n), np.float32)
    stretch[11:14, 5:20] = 50.0
    assert not stick_through(stretch, 0, 0, c, r, thresh)
    assert not stick_through(stretch, 0, 0, c, r, thresh, np.full_like(felt, 100.0))  # a bare felt adds nothing
    assert stick_through(stretch, 0, 0, c, r, thresh, felt)
    yy, xx = np.mgrid[:n, :n]
    ball = np.where(np.hypot(xx - c[0], yy - c[1]) <= r, 40.0, 0.0).astype(np.float32)
    assert not stick_through(ball, 0, 0, c, r, thresh, felt)


def _band(xx, yy, c, ang, width, offset, start=None, stop=None):
    """Coverage (0-1, area-weighted edges) of a band ``width`` px wide along
    angle ``ang``, its centre line ``offset`` px beside ``c``, from ``start``
    to ``stop`` px along it (None: the window's edge)."""
    ux, uy = np.cos(ang), np.sin(ang)
    perp = -(xx - c[0]) * uy + (yy - c[1]) * ux
    along = (xx - c[0]) * ux + (yy - c[1]) * uy
    cov = np.clip(width / 2 + 0.5 - np.abs(perp - offset), 0, 1)
    if start is not None:
        cov = cov * np.clip(along - start + 0.5, 0, 1)
    if stop is not None:
        cov = cov * np.clip(stop - along + 0.5, 0, 1)
    return cov


def _felt_joined_cases(n_cases=600, seed=7):
    """Pairs of (ball, stretch) windows for stick_through's felt-joined pass
    (``STICK_JOINED_WIDTH_RADII``): each a list of ``(D, felt, u0, v0, c, r,
    thresh)``.  Balls: the lit sphere (SphereLook, streak_model) with the
    tracker's threshold rule, every other one the review's dim ball (0.3 +
    0.7 cos shading, 40-120 levels, threshold 32: a half-disc or less over
    it), beside a feature of the ball's sign in the felt: a still cue ending
    at its rim (0.2-1 r wide), a line (1-4 px, 0-1.1 r from the centre) or a
    cushion band (2-10 px, 1-6 px beyond the rim).  Stretches: the cue clip's
    (0.35-0.7 r wide, 1.2-2.2 thresholds deep) ending inside the window, the
    felt's still cue (0.9-1.2 times as wide) from there to the border."""
    from cuespin.track.model import SphereLook, streak_model
    from cuespin.track.tracker import STICK_GAP_PX

    rng = np.random.default_rng(seed)
    u0, v0 = 500, 283
    balls, stretches = [], []
    for i in range(n_cases):
        r = rng.uniform(6, 15)
        half = int(np.ceil(r + STICK_GAP_PX))
        n = 2 * half + 1
        c = np.array([u0 + half + rng.uniform(-.5, .5), v0 + half + rng.uniform(-.5, .5)])
        yy, xx = np.mgrid[v0:v0 + n, u0:u0 + n].astype(float)
        sigma = rng.uniform(1, 5)
        look = SphereLook(rng.uniform(0, 2 * np.pi), rng.uniform(0.4, 1.2), 40.0)
        geo = np.r_[rng.uniform(20, 70), 120.0, 0.0, look.geometry()]
        G = rng.uniform(75, 130)
        D = streak_model(c, np.zeros(2), G, np.full((n, n), 60.0), r, u0, v0, np.zeros(1), geo)[0]
        disc = np.hypot(xx - c[0], yy - c[1]) <= r
        thresh = max(5 * sigma, 0.25 * np.percentile(D[disc], 75))  # foreign_threshold's rule
        if i % 2:
            light = rng.uniform(0, 2 * np.pi)
            lx, ly = np.cos(light), np.sin(light)
            thresh, sigma = 32.0, rng.uniform(1, 6.4)
            shade = np.clip(0.3 + 0.7 * ((xx - c[0]) * lx + (yy - c[1]) * ly) / r, 0, None)
            D = np.where(disc, rng.uniform(40, 120) * shade, 0.0)
        D = (D + rng.normal(0, sigma, D.shape)).astype(np.float32)
        kind, ang, w = rng.integers(3), rng.uniform(0, np.pi), rng.uniform(0.2, 1.0) * r
        amp = thresh * rng.uniform(1.2, 2.5)
        if kind == 0:
            cov = _band(xx, yy, c, ang, w, rng.uniform(-.3, .3) * r, start=r * rng.uniform(0.8, 1.1))
        elif kind == 1:
            cov = _band(xx, yy, c, ang, rng.uniform(1, 4), rng.uniform(0, 1.1) * r)
        else:
            cov = _band(xx, yy, c, ang, rng.uniform(2, 10), r + rng.uniform(1, 6))
        felt = (100 + amp * cov + rng.normal(0, sigma, (n, n))).astype(np.float32)
        balls.append((D, felt, u0, v0, c, r, thresh))
        w, off = rng.uniform(0.35, 0.7) * r, rng.uniform(-0.3, 0.3) * r
        a0, a1 = rng.uniform(-0.8, 0.2) * r, rng.uniform(0.3, 0.9) * (half - 1)
        amp = thresh * rng.uniform(1.2, 2.2)
        S = amp * _band(xx, yy, c, ang, w, off, start=a0, stop=a1) + rng.normal(0, sigma, (n, n))
        still = _band(xx, yy, c, ang, w * rng.uniform(0.9, 1.2), off, start=a1)
        felt = (100 + amp * still + rng.normal(0, sigma, (n, n))).astype(np.float32)
        stretches.append((S.astype(np.float32), felt, u0, v0, c, r, thresh))
    return balls, stretches


def test_the_felt_joined_pass_tells_a_dim_ball_beside_a_line_from_the_cues_stretch():
    # A half-lit ball alone is 0.92 r wide (sqrt(12 * 0.07) r), so joined to
    # a line, a cushion or a still cue in the felt it fell under the lone
    # blob's STICK_WIDTH_RADII (1): a lost frame.  Measured on 2,000 pairs
    # (seed 11): limit 1.0 -> 192 balls newly called a stick (9.6%), 16
    # stretches missed; STICK_JOINED_WIDTH_RADII 0.75 -> 44 (2.2%) and 22
    # (1.1%; 16 of them missed at any limit: the stretch does not join the
    # still cue above the threshold).  Bounds here (600 pairs, seed 7: 13
    # and 8; 61 balls at 1.0): those rates plus three binomial standard
    # errors at n = 600.
    from cuespin.track import tracker
    from cuespin.track.tracker import stick_through

    balls, stretches = _felt_joined_cases()
    n = len(balls)
    called = sum(stick_through(b[0], *b[2:], b[1]) and not stick_through(b[0], *b[2:]) for b in balls)
    missed = sum(not stick_through(s[0], *s[2:], s[1]) for s in stretches)
    assert called <= n * (0.022 + 3 * np.sqrt(0.022 * 0.978 / n)), (called, n)
    assert missed <= n * (0.011 + 3 * np.sqrt(0.011 * 0.989 / n)), (missed, n)
    assert tracker.STICK_JOINED_WIDTH_RADII < tracker.STICK_WIDTH_RADII


def test_the_felts_ghost_of_a_resting_ball_is_left_out_not_a_dark_rim():
    # The felt learnt around a ball at rest holds speckles of it
    # (sample_scenes(6, 7, realistic, MJPG)[4]: 150-210 levels over the felt
    # beside them); once the ball has left, felt_ghost finds those the frame
    # shows as felt.  A shaded ball's dark rim over a clean felt, below the
    # felt by as much, is the ball's own and is kept.
    from cuespin.track.tracker import felt_ghost

    rng = np.random.default_rng(3)
    n, r, level, ball, thresh = 41, 7.6, 60.0, 230.0, 50.0
    v, u = np.mgrid[:n, :n]
    felt = level + rng.normal(0, 1.2, (n, n))
    rest = np.hypot(u - 18.0, v - 18.0) <= r
    speckle = rest & (rng.random((n, n)) < 0.5)
    ghosted = np.where(speckle, ball, felt)
    moved = np.hypot(u - 22.5, v - 22.5) <= r  # 0.84 radii on
    frame = np.where(moved, ball, felt + rng.normal(0, 1.2, (n, n)))
    g = felt_ghost(frame, ghosted, 1, thresh)
    assert g is not None
    assert np.array_equal(g, speckle & ~moved)  # under the ball now, the speckles agree with the frame
    assert felt_ghost(frame, felt, 1, thresh) is None  # a clean felt holds nothing
    # A shaded ball: a bright middle, a rim 80 levels under the felt.
    d = np.hypot(u - 20.0, v - 20.0) / r
    shaded = np.where(d <= 1, level + 150 * (1 - d) - 80 * d, felt)
    assert (shaded - felt < -thresh).any()
    assert felt_ghost(shaded, felt, 1, thresh) is None
    # Nor a dark ball (polarity -1) against its own clean felt.
    assert felt_ghost(2 * level - shaded, 2 * level - felt, -1, thresh) is None


@pytest.mark.parametrize("layout", ["bgr0 view", "grey"])
def test_felt_accumulator_sums_any_frame_layout(layout):
    """add_frame's compiled sum reads a frame's levels in memory order: a
    4-channel frame's BGR view (not contiguous) and a grey frame sum as
    numpy sums them."""
    from cuespin.track.background import FeltAccumulator

    rng = np.random.default_rng(5)
    shape = (24, 32, 3) if layout == "bgr0 view" else (24, 32)
    felt = FeltAccumulator(shape)
    ref = np.zeros(shape, np.float64)
    for _ in range(5):
        raw = rng.integers(0, 256, (24, 32, 4) if layout == "bgr0 view" else shape, dtype=np.uint8)
        frame = raw[:, :, :3] if layout == "bgr0 view" else raw
        centre = rng.uniform((0.0, 0.0), (32.0, 24.0))
        felt.add_frame(frame, centre, 4.0)
        out = FeltAccumulator._disc(0, 0, 24, 32, centre, 4.0)
        ref += frame
        ref[out] -= frame[out]
    felt._carry()
    assert np.array_equal(felt.full, ref.astype(np.float32))


@pytest.mark.parametrize("tolerance", [6.3, np.float64(6.3), np.inf])
@pytest.mark.parametrize("with_exclude", [False, True])
@pytest.mark.parametrize("with_reference", [False, True])
def test_felt_accumulator_adds_windows_as_numpy(tolerance, with_exclude, with_reference):
    """add's compiled pass (track.window.felt_add) gives numpy's masks' sums
    and counts bit for bit: the disc's squares in float64, the reference
    compared in the dtype numpy compares in (float32 with a Python float,
    float64 with a numpy float64), left-out pixels adding 0."""
    from cuespin.track.background import FeltAccumulator

    rng = np.random.default_rng(11)
    H, W = 40, 56
    felt = FeltAccumulator((H, W, 3))
    total = np.zeros((H, W), np.float32)
    count = np.zeros((H, W), np.int32)
    # Levels 0 and 1 and steps of float32(6.3): differences exactly on the
    # tolerance's float32 value, which float64's 6.3 lies under.
    reference = rng.integers(0, 2, (H, W)).astype(np.float32) if with_reference else None
    for _ in range(30):
        h, w = rng.integers(5, 20, 2)
        u0, v0 = int(rng.integers(0, W - w)), int(rng.integers(0, H - h))
        base = reference[v0:v0 + h, u0:u0 + w] if with_reference else np.ones((h, w), np.float32)
        step = np.float32(6.3) * rng.choice(np.array([-1.0, 1.0, 0.0, 7.0], np.float32), (h, w))
        patch = base + step
        exclude = rng.random((h, w)) < 0.2 if with_exclude else None
        centre = rng.uniform((u0, v0), (u0 + w, v0 + h))
        radius = float(rng.uniform(1.0, 8.0))
        felt.add(patch, u0, v0, centre, radius, exclude, reference, tolerance)
        FeltAccumulator.add_numpy(total, count, patch, u0, v0, centre, radius, exclude, reference, tolerance)
    assert felt.n == 30
    assert np.array_equal(felt.count, count)
    assert np.array_equal(felt.total, total)
    assert np.array_equal(np.signbit(felt.total), np.signbit(total))
