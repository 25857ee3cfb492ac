"""The tracker on the renderer's realistic look, end to end (render, codec, track).

Issue 10's targets on realistic renders: the ball found in at least 99% of
the frames where it is wholly in view, and no false positive (a found centre
more than a quarter radius from the truth).

The fast cases are the data generator's realistic MJPG scenes (seed 5) that
failed: other balls at rest, off the path, whose colour stands out from the
felt as much as the struck ball's or more (shot 1: a yellow ball beside a
yellow one; shot 4: a red ball beside a white one).  The background learnt
from the look-ahead took them for felt the ball had hidden and filled them
in, so they became the most ball-like blobs: shot 1 tracked the resting ball
211 px off in every frame, shot 4 found two blobs in every frame and no ball.
"""

import numpy as np
import pandas as pd
import pytest

from cuespin.data_gen.sampler import sample_scenes
from cuespin.render import render_video
from cuespin.render.draw import FrameRenderer
from cuespin.track.tracker import OK, TrackerConfig, pulled_fits
from cuespin.track.video import track_video

# Issue 10: the share of the frames where the ball is wholly in view and on
# open cloth that it must be found in, and the largest error of a found
# centre, in ball radii.
MIN_FOUND = 0.99
MAX_ERR_RADII = 0.25
# The ball is touched by the cue (not on open cloth) while the cue's tip is
# within this many px of the ball's surface along the shot line: the
# realistic look's optical blur (PSF sigma 0.5-1.5 px) joins the two images
# there.  Such frames may be left out (a status other than ok); a centre
# reported in them must still be right.
CUE_TOUCH_PX = 2.0


def open_cloth(scene, truth, r_px: float) -> np.ndarray:
    """Frames (bool) where the ball is on open cloth, from the truth and the
    scene's render block: the cue's tip (the renderer's own ``cue_tip``, its
    distance behind the rest's contact point, plus how far the ball has
    moved along the shot line) farther than ``CUE_TOUCH_PX`` from the ball's
    surface, and no resting ball's image within a diameter and
    ``CUE_TOUCH_PX`` of the ball's centre."""
    out = np.ones(len(truth), bool)
    look, R, tr = scene.render, scene.physics.R, scene.truth
    if look.get("cue"):
        v0 = np.asarray(tr.v0, float)
        d = v0 / np.hypot(*v0)
        moved = (np.c_[truth.x_m.values, truth.y_m.values] - np.asarray(tr.x0)) @ d
        gap_px = (FrameRenderer(scene).cue_tip(truth.t.values) + moved) * r_px / R
        out &= gap_px > CUE_TOUCH_PX
    uv = np.c_[truth.uc_px.values, truth.vc_px.values]
    for b in look.get("balls", []):
        buv = np.asarray(scene.camera.to_pixels(np.array([[b["x"], b["y"]]])))[0]
        out &= np.hypot(*(uv - buv).T) > 2 * r_px + CUE_TOUCH_PX
    return out


def track_against_truth(scene, path, counts: bool = False):
    """Render ``scene`` to ``path``, track it, and return (found share among
    the frames where the ball is wholly in view and on open cloth, errors of
    the found centres in radii, the result); with ``counts`` the share as
    (found, frames)."""
    render_video(scene, path)
    tr = track_video(path, scene, TrackerConfig(threaded=False))
    truth = pd.read_csv(path.with_suffix(".truth.csv"))
    n = min(tr.n_frames, len(truth))
    truth = truth.iloc[:n]
    tuv = np.c_[truth.uc_px.values, truth.vc_px.values]
    cam, r = scene.camera, tr.radius_px
    in_view = ((tuv[:, 0] >= r) & (tuv[:, 0] <= cam.width - 1 - r)
               & (tuv[:, 1] >= r) & (tuv[:, 1] <= cam.height - 1 - r))
    counted = in_view & open_cloth(scene, truth, r)
    ok = tr.ok[:n]
    err = np.hypot(*(tr.uv[:n] - tuv).T)[ok] / r
    found = (int(ok[counted].sum()), int(counted.sum())) if counts else ok[counted].mean()
    return found, err, tr


def assert_issue_targets(found, err, tr, what):
    assert found >= MIN_FOUND, f"{what}: found in {found:.1%} of the frames in view ({tr.status_counts()})"
    assert err.size and err.max() < MAX_ERR_RADII, f"{what}: a found centre {err.max():.2f} radii off"


@pytest.mark.parametrize("shot, seconds", [(1, 0.6), (4, 0.5)])
def test_resting_balls_that_outshine_the_ball_are_not_tracked(tmp_path, shot, seconds):
    scene = sample_scenes(shot + 1, 5, look="realistic", codec="MJPG")[shot]
    assert len(scene.render["balls"]) >= 2  # the failing feature: balls at rest off the path
    scene.render["max_duration"] = seconds  # the strike and some rolling, few frames
    found, err, tr = track_against_truth(scene, tmp_path / f"shot{shot}.avi")
    assert_issue_targets(found, err, tr, f"seed 5 shot {shot}")


# The sets whose targets are not met yet, as measured (README, Known
# limits): strict, so that a fix shows as a pass to be unmarked.
# [7-FFV1] unmarked: it passed (XPASS, strict) on main a7cd771 after found12 (lead, 342 s at low load).
NOT_YET: dict = {}


@pytest.mark.slow
@pytest.mark.parametrize("codec", ["MJPG", "FFV1"])
@pytest.mark.parametrize("seed", [5, 6, 7])
def test_realistic_shots_meet_the_issue_targets(tmp_path, seed, codec, request):
    if (seed, codec) in NOT_YET:
        request.applymarker(pytest.mark.xfail(reason=NOT_YET[seed, codec], strict=True))
    found = frames = 0
    for i, scene in enumerate(sample_scenes(6, seed, look="realistic", codec=codec)):
        scene.render["max_duration"] = 2.0
        (f, m), err, tr = track_against_truth(scene, tmp_path / f"shot{i}.avi", counts=True)
        # Every shot: an answer, and no centre more than a quarter radius off.
        assert err.size and err.max() < MAX_ERR_RADII, \
            f"seed {seed} {codec} shot {i}: " + (f"a found centre {err.max():.2f} radii off" if err.size
                                                 else f"no ball found ({tr.status_counts()})")
        found, frames = found + f, frames + m
    # The issue's share over the set's frames on open cloth (one shot's few
    # frames, 51 at 60 fps, would make a single lost frame 2%).
    assert found >= MIN_FOUND * frames, f"seed {seed} {codec}: found in {found} of {frames} frames"


def test_cue_tip_at_the_strike_is_not_the_ball(tmp_path):
    # sample_scene(3, realistic, FFV1): an orange ball on red felt (noise
    # 6.7, 120 fps) struck by a cue whose tip follows it through.  Before
    # the fix the cue, in the felt's average and in the ball's window, moved
    # found centres 3-11 px (0.4-1.2 radii) off at and after the strike.
    from cuespin.data_gen.sampler import sample_scene

    scene = sample_scene(3, look="realistic", codec="FFV1")
    assert scene.render["cue"]
    scene.render["max_duration"] = 0.6  # rest, strike at frame 35, follow-through, withdrawal
    found, err, tr = track_against_truth(scene, tmp_path / "cue.avi")
    assert err.size and err.max() < MAX_ERR_RADII, f"a found centre {err.max():.2f} radii off"
    # Measured 72 of 73 frames in view (one fit fails as the cue touches):
    # a frame left out is allowed, a wrong centre is not.
    assert found >= 0.95, tr.status_counts()


# The largest mean error (radii, a vector's length) of the found centres on
# seed 8 shot 19's MJPG cut: a steady pull towards the lit side was the bug.
# Measured on this 0.5-s cut (rev13v, docs/measurements.md): before fp13's
# fix (2189b4e^1) 0.210 R over its 10 found frames, after 0.0026 R over 61
# (the review's 0.011-0.018 R on other cuts); 0.05 lies well between.
MEAN_BIAS_RADII = 0.05


def test_a_shaded_red_ball_on_red_felt_in_mjpg_is_not_fitted_towards_its_lit_side(tmp_path):
    # benchmarks/track.py realistic seed 8 shot 19 (a red ball on red felt,
    # lens blur 0.962 px, 120 fps, noise 2.9), written as MJPG and cut to
    # 0.5 s (the rest, the strike at 0.41 s, 11 frames rolling).  In the
    # white-free channel (MJPG's chroma) the felt lies at 0.63 of the lit
    # ball's level: the ball's darker side faded into the felt, the codec
    # kept its lit side, and the 0.8-s clip was fitted 0.17-0.26 radii
    # towards the light in every frame (48 of 97 beyond a quarter radius).
    # Now the channel is blind to the felt's colour (colour.FELT_SHADE_MIN).
    # Measured on this clip: before, 10 of 61 frames found, 4 of them
    # 0.25-0.43 radii off; after, 61 of 61, the largest error 0.079 radii.
    scene = sample_scenes(20, 8, look="realistic", codec="MJPG")[19]
    assert (scene.render["ball_name"], scene.render["felt_name"]) == ("red", "red")
    scene.render.update(specular=0.0, markings="none", psf_sigma=0.962, cue=False, balls=[], max_duration=0.5)
    found, err, tr = track_against_truth(scene, tmp_path / "red.avi")
    assert_issue_targets(found, err, tr, "seed 8 shot 19 MJPG")
    # The bug was a steady pull towards the light, so the found centres' mean
    # error (a vector) is asserted too: MEAN_BIAS_RADII.
    truth = pd.read_csv((tmp_path / "red.avi").with_suffix(".truth.csv"))
    n = min(tr.n_frames, len(truth))
    ok = tr.ok[:n]
    bias = (tr.uv[:n] - np.c_[truth.uc_px.values, truth.vc_px.values][:n])[ok].mean(axis=0) / tr.radius_px
    assert np.hypot(*bias) < MEAN_BIAS_RADII, f"the found centres' mean error {np.hypot(*bias):.3f} radii"


# Slow (rev13v): 20-85 s by the review's timing, and it cannot be cut
# shorter: the frames that were dropped (19 and 20, 0.32-0.33 s) lie at the
# cut's end and the strike (0.195 s) and the look-ahead before it come first.
@pytest.mark.slow
def test_a_logo_on_the_rim_of_a_rolling_ball_does_not_drop_its_frames(tmp_path):
    # benchmarks/track.py realistic seed 7 shot 3: a yellow ball with a logo
    # on grey felt, 60 fps, noise 7.7, FFV1, struck at t0 = 0.195 s.  The
    # ball rolls with the logo on its lower rim; there the first fit is
    # pulled 1.7-2.5 px (0.14-0.21 R), the markings judged from that centre
    # are refused and the frame was dropped as pulled (0.8 s: 38 of 49 in
    # view found).  In this 0.36 s cut, measured: before, frames 19 and 20
    # dropped (and 6, at rest); after (the retry from the prediction on a
    # marked ball, the rim's refit kept beside the prediction, the better of
    # two agreeing fits), every moving frame found, the largest error
    # 0.145 px (0.012 R); frame 6 still dropped by the recentring (its
    # second fit fails: not this fix).  Asserted: every frame 0.02 s after
    # the strike found, none 0.05 R off.
    scene = sample_scenes(4, 7, look="realistic", codec="FFV1")[3]
    scene.render.update(specular=0.0, psf_sigma=0.0, markings="logo", cue=False, balls=[], max_duration=0.36)
    render_video(scene, tmp_path / "logo.avi")
    tr = track_video(tmp_path / "logo.avi", scene, TrackerConfig(threaded=False))
    truth = pd.read_csv((tmp_path / "logo.avi").with_suffix(".truth.csv"))
    n = min(tr.n_frames, len(truth))
    moving = truth.t.values[:n] > scene.truth.t0 + 0.02
    assert moving.sum() >= 9
    assert tr.ok[:n][moving].all(), f"moving frames {np.flatnonzero(moving & ~tr.ok[:n])} dropped"
    err = np.hypot(*(tr.uv[:n] - np.c_[truth.uc_px.values, truth.vc_px.values][:n]).T)[moving] / tr.radius_px
    assert err.max() < 0.05, f"a moving centre {err.max():.3f} radii off"


@pytest.mark.slow
def test_dots_on_a_white_ball_do_not_pull_the_centre(tmp_path):
    # benchmarks/track.py realistic seed 0 shot 18: a white ball with dots
    # on blue felt, 240 fps, noise 1.7, no cue.  Before the markings were
    # left out of the fit (track.tracker.marking_pixels) 10 frames were
    # 0.27-0.30 radii off (the shaded fit stopped in a wrong minimum with a
    # dot in view) and 97.9% found; after, measured 100% found, the largest
    # error 0.034 radii: three times that allowed.
    scene = sample_scenes(19, 0, look="realistic", codec="FFV1")[18]
    scene.render.update(specular=0.0, psf_sigma=0.0, markings="dots", cue=False, balls=[], max_duration=0.8)
    found, err, tr = track_against_truth(scene, tmp_path / "dots.avi")
    assert found >= MIN_FOUND, tr.status_counts()
    assert err.size and err.max() < 0.1, f"a found centre {err.max():.3f} radii off"


@pytest.mark.slow
def test_the_frame_after_the_strike_is_fitted_at_its_own_streak(tmp_path):
    # benchmarks/track.py realistic seed 0 shot 8: a white ball with a logo
    # on green felt, 120 fps, exposure 0.53 frames, struck at t0 = 0.4314 s
    # (frame 52 holds the strike in its exposure).  Frame 53's streak was
    # predicted from frames 51-52 (52's centre had moved 1.9 px of a 7-px
    # step): held at 1.0 px where it is 3.7 px, the fit took the streak's
    # misfit for markings, stated 4.5 times the track's median error and
    # was dropped as ill determined (0.13 px off; 95 of 97 found).  Refitted
    # at the streak its own step gives (BallTracker._seen_blur): measured
    # 0.022 px off and kept.  The strike's own frame may be left out (its
    # ball accelerates within the exposure); every other frame must be found.
    scene = sample_scenes(9, 0, look="realistic", codec="FFV1")[8]
    scene.render.update(specular=0.0, psf_sigma=0.0, markings="logo", cue=False, balls=[], max_duration=0.8)
    (found, frames), err, tr = track_against_truth(scene, tmp_path / "strike.avi", counts=True)
    assert err.size and err.max() < MAX_ERR_RADII, f"a found centre {err.max():.2f} radii off"
    assert tr.ok[53] and found >= frames - 1, (found, frames, tr.status[50:56])


@pytest.mark.slow
def test_the_felts_ghost_of_the_rest_does_not_hold_the_leaving_ball_back(tmp_path):
    # sample_scenes(6, 7, realistic, MJPG)[4]: a white ball with dots at rest
    # for 0.45 s at 480 fps, the cue following through behind it.  The felt
    # learnt around the resting ball holds speckles of it; as the ball left,
    # its fits were held back towards the rest spot (frames 223-227 of the
    # 2-s video 0.30-0.45 radii off; of this 0.6-s clip 226 and 227, 0.34 and
    # 0.40, and 223-225 dropped as pulled).  With those pixels left out
    # (track.tracker.felt_ghost) measured: 284 of 289 frames ok, none off by
    # more than 0.098 radii (docs/measurements.md, false9).
    scene = sample_scenes(5, 7, look="realistic", codec="MJPG")[4]
    scene.render["max_duration"] = 0.6
    found, err, tr = track_against_truth(scene, tmp_path / "ghost.avi")
    assert_issue_targets(found, err, tr, "seed 7 MJPG shot 4, 0.6 s")


@pytest.mark.slow
# Passed on the renders of branch fp4 (47 of 81 found, none off), then
# failed on the compiled noise's draw (the crescent in the first two ok
# frames, 1.3-1.4 radii ahead along the path) and was marked xfail; passes
# again on main 3a88a64 (XPASS, strict: 63 of 81 found, largest 0.245 R) and
# after found12's search at the departure's centroid (73 of 81, the same
# largest): unmarked (docs/measurements.md, found12).
def test_red_ball_on_red_felt_in_low_light_reports_no_false_centre(tmp_path):
    # sample_scenes(6, 7, realistic, MJPG)[5]: a red ball on red felt under
    # a low light (ambient 0.39), 60 fps, no cue: its lit middle is brighter
    # than the felt and its rim darker, and the search's blob was the rim's
    # crescent: 43 of 81 frames were reported 1.3-1.4 radii off.  Now the
    # fit is tried again from the centroid of the departure in either
    # direction, and a frame whose two fits disagree is dropped (44 of 81
    # found, 5 of them still the crescent's), and a centre off the path its
    # neighbours trace is dropped (track.path: measured 47 of 81 found, none
    # off); a frame left out is allowed, a wrong centre is not.
    scene = sample_scenes(6, 7, look="realistic", codec="MJPG")[5]
    scene.render["max_duration"] = 2.0
    found, err, tr = track_against_truth(scene, tmp_path / "red.avi")
    assert err.size and err.max() < MAX_ERR_RADII, f"a found centre {err.max():.2f} radii off"
    assert found >= 0.3, tr.status_counts()


@pytest.mark.slow
@pytest.mark.parametrize("codec, suffix, floor", [
    # Floors measured with the threshold from the ball's own score (thresh):
    # H.264 70 and FFV1 66 of 120 found (the ball on the cloth ~70 frames);
    # with the threshold from the swept contrast they were 47 and 32.
    ("H264", ".mp4", 65), ("FFV1", ".avi", 62)])
def test_red_ball_on_red_felt_in_h264_reports_no_false_centre(tmp_path, codec, suffix, floor):
    # sample_scene(14, realistic) in H.264 (yuv420p), 120 frames: a red ball
    # on red felt whose middle is brighter than the felt and rim darker in
    # the learnt channel, rolling over the cushion and out of the frame at
    # frame ~72.  Before the learnt contrast was taken on the ball's side of
    # the felt only, it read 6 (the ball's middle departs by ~125): 47 of
    # 120 frames found, 18 of them a pocket or plain felt, 545 px off, and
    # the rest frames dropped as "pulled" against the pocket's fits.
    # Measured with the contrast from the ball-side pixels: 65 found, none
    # off more than 2.5 px (0.21 radii); with the swept pixels' (main, since
    # contrast3) 47, none off more than 1.1 px: the threshold, a quarter of
    # 106, was above this shaded ball's score (28) in most moving frames.
    # With the threshold from the ball's own score in the samples (0.3 of
    # it, 8.3): 70 found (every frame with the ball on the cloth), none off
    # more than 1.1 px.
    from cuespin.data_gen.sampler import sample_scene

    scene = sample_scene(14, look="realistic", codec=codec)
    path = tmp_path / ("red" + suffix)
    render_video(scene, path, n_frames=120)
    tr = track_video(path, scene, TrackerConfig(threaded=False))
    truth = pd.read_csv(path.with_suffix(".truth.csv")).iloc[:tr.n_frames]
    err = np.hypot(*(tr.uv - np.c_[truth.uc_px.values, truth.vc_px.values]).T)[tr.ok] / tr.radius_px
    assert err.size and err.max() < MAX_ERR_RADII, f"a found centre {err.max():.2f} radii off"
    assert tr.ok.sum() >= floor, tr.status_counts()


@pytest.fixture(scope="module")
def cue_shot():
    """sample_scenes(6, 6, realistic, FFV1)[0], its first 0.8 s, with the
    projection, felt, contrast and detection score learnt from its own
    frames by track_video's learning (learn_model): the thresholds the
    tracker uses, not hand-set ones."""
    from cuespin.track.tracker import TrackerConfig
    from cuespin.track.video import learn_model, search_mask

    scene = sample_scenes(1, 6, look="realistic", codec="FFV1")[0]
    assert scene.render["cue"]
    scene.render["max_duration"] = 0.8  # strike at 0.31 s: the cue drawn back and coming in, then the ball moves
    fr = FrameRenderer(scene)

    class Frames:  # rendered on demand: learning reads only its samples (~20 of 96 frames)
        def __len__(self):
            return len(fr.truth.t)

        def __getitem__(self, k):
            return fr.render(k, np.random.default_rng([6, k]))

    frames = Frames()
    cam, R = scene.camera, scene.physics.R
    r = R * cam.px_per_m(scene.truth.x0)
    mask = search_mask(cam, scene.table, R, frames[0].shape[:2])  # the playing surface, as track_video's
    proj, bg = learn_model(frames, r, TrackerConfig().n_background, mask)
    assert bg.polarity and bg.score > 0  # the ball seen moving, with its own detection score
    return frames, fr.truth.uvc, r, mask, proj, bg


@pytest.mark.parametrize("k", [0, 20, 29])
def test_cue_shaft_is_not_the_ball(cue_shot, k):
    # A blue ball with dots on blue felt and a tan cue, before the strike:
    # the ball is found, not the shaft; with the ball hidden (its window
    # copied into the felt), the shaft alone is no ball.
    from dataclasses import replace

    from cuespin.track.tracker import NO_BALL, OK, BallTracker

    frames, uvc, r, mask, proj, bg = cue_shot
    frame, truth = frames[k], uvc[k]
    loc, status = BallTracker(bg, r, 0.5, projection=proj, search_mask=mask)._full_search(frame)
    # Frames 0-7 (the cue still at address, its tip 3.4 radii behind the
    # ball) were "two ball-like blobs": the felt holds the cue where it is
    # held after the strike, and the stretch the address reaches beyond
    # that was the second blob.  Joined to the felt's still cue it runs
    # through the ball's window (stick_through's ``felt``): the ball alone.
    assert status == OK, (k, loc, status)
    assert np.hypot(*(loc - truth)) < 0.5 * r, (k, loc, status)  # a blob, refined later
    hidden = bg.image.copy()
    u, v, h = int(round(truth[0])), int(round(truth[1])), int(2 * r)
    hidden[v - h:v + h + 1, u - h:u + h + 1] = proj(frame)[v - h:v + h + 1, u - h:u + h + 1]
    loc, status = BallTracker(replace(bg, image=hidden), r, 0.5, projection=proj, search_mask=mask)._full_search(frame)
    assert status == NO_BALL, (k, loc, status)


@pytest.mark.slow
def test_every_found_frame_states_a_positive_definite_error(tmp_path):
    # benchmarks/accuracy.py --look realistic --codec FFV1 --seed 22, shot 16
    # (6 s at most, as there): the lit sphere's refits of the voting frames
    # and the felt-corrected refits gave 16 found frames indefinite
    # covariances (variances -49 to 7e10 px^2), on which the recovery's
    # Cholesky raised.  A refit that states no error is not taken (the
    # frame keeps its first fit): 728 found, all positive definite.
    scene = sample_scenes(17, 22, look="realistic")[16]
    scene.render["max_duration"] = 6.0
    scene.render["codec"] = "FFV1"
    video = tmp_path / "shot16.avi"
    render_video(scene, video)
    tr = track_video(video, scene, TrackerConfig())
    c = tr.cov_px[tr.ok]
    assert tr.ok.sum() >= 0.97 * len(tr.ok)  # measured 728 of 736 (0.989); the refits taken unchecked: 713 (0.969)
    assert np.all(np.isfinite(c)) and np.all(c[:, 0, 0] > 0) and np.all(np.linalg.det(c) > 0)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "issue 10, since marks7's rim markings: this clip's fits are now tight (quartiles 1.16-1.22 levels over its "
    "241 fitted frames) and 4 correct frames (59, 154, 156, 184; within 0.01 R) at 3.5-4.5 levels pass 3 times "
    "the best quarter's: dropped, by the rule before review 10a's quartile change too (lead, measured)"))
def test_the_pulled_rule_drops_fits_off_the_ball_not_a_turning_look(tmp_path, monkeypatch):
    # track.tracker.pulled_fits' two error rates on the generator's track
    # that broke it (sample_scenes(6, 6, realistic, FFV1)[1], a dotted ball
    # rolling at 240 fps, the lit sphere's learnt PSF; its first second):
    # the frames it drops that were right (the dots unfound at the rim
    # raise a correct fit's residual: against 3 times the best quarter's,
    # 35 of the 2-s shot's 481 were dropped, all within 0.007 R), and the
    # fits 0.25 R off (issue 10's false centre) it would keep: each final
    # refit's window explained with its centre held that far off in 8
    # directions (level and look refitted, linear at the fixed centre),
    # its residual RMS the fit's times the ratio of the two linear fits'.
    from cuespin.track import video
    from cuespin.track.model import SphereLook, _model_rows, blur_nodes

    scene = sample_scenes(2, 6, look="realistic", codec="FFV1")[1]
    scene.render["max_duration"] = 1.0
    path = tmp_path / "dots.avi"
    render_video(scene, path)
    off = 0.25 * np.c_[np.cos(np.arange(8) * np.pi / 4), np.sin(np.arange(8) * np.pi / 4)]

    def linear_rms(patch, felt, u0, v0, c, b, r, shade, outline, valid):
        look = np.array(shade, float)
        look[:3] = 0.0  # the look's coefficients refitted below, with the level
        m0, JT = _model_rows(c, b, 0.0, felt, r, u0, v0, blur_nodes(np.hypot(*b)), look, False, outline)
        y = (np.asarray(patch, float) - felt - m0).ravel()
        use = np.ones(len(y), bool) if valid is None else np.asarray(valid, bool).ravel()
        A = JT[2:6].T[use]
        e = y[use] - A @ np.linalg.lstsq(A, y[use], rcond=1e-9)[0]
        return np.sqrt(np.mean(e ** 2))

    held, seen = [], {}
    fit_disc = video.fit_disc

    def fit_and_hold(patch, felt, u0, v0, c0, r, G, **kw):
        g = fit_disc(patch, felt, u0, v0, c0, r, G, **kw)
        if not (g and g.stated):
            held.append(None)  # the frame keeps its first fit (track_video): not measured
            return g
        shade, outline = kw.get("shade"), kw.get("outline")
        rr = outline.radius if isinstance(shade, SphereLook) and outline is not None else r
        args = (patch, felt, u0, v0)
        at = linear_rms(*args, g.c, g.b, rr, g.shade, outline, kw.get("valid"))
        held.append([g.rms * linear_rms(*args, g.c + d * r, g.b, rr, g.shade, outline, kw.get("valid")) / at
                     for d in off])
        return g

    def keep_all(rms, ok, still=None, se=None):
        seen.update(rms=np.array(rms), ok=np.array(ok), still=np.array(still), se=np.array(se))
        return np.zeros(len(rms), bool)

    monkeypatch.setattr(video, "fit_disc", fit_and_hold)
    monkeypatch.setattr(video, "pulled_fits", keep_all)
    tr = track_video(path, scene, TrackerConfig(threaded=False))
    rms, ok, still = seen["rms"], seen["ok"], seen["still"]
    truth = pd.read_csv(path.with_suffix(".truth.csv")).iloc[:tr.n_frames]
    err = np.hypot(*(tr.uv - np.c_[truth.uc_px.values, truth.vc_px.values]).T) / tr.radius_px
    fitted = np.flatnonzero(ok & np.isfinite(rms))
    assert len(held) == len(fitted) and err[fitted].max() < MAX_ERR_RADII  # every frame refitted, none off
    dropped = pulled_fits(rms, ok, still=still)
    assert not dropped.any(), f"{dropped.sum()} correct frames dropped (rms {np.round(rms[dropped], 2)})"
    # The ill-determined centre's rule (red8) drops none of them either.
    assert not pulled_fits(rms, ok, still=still, se=seen["se"]).any()
    kept, measured = 0, [(k, h) for k, h in zip(fitted, held) if h is not None]
    assert len(measured) >= 0.95 * len(fitted)
    for k, h in measured:
        for v in h:
            r = rms.copy()
            r[k] = v
            kept += not pulled_fits(r, ok, still=still)[k]
    assert kept == 0, f"{kept} of {len(off) * len(measured)} fits held 0.25 R off kept"


def _track_errors(scene, path):
    """Render ``scene`` to ``path`` (FFV1) and track it: the track, each
    frame's error (px, (n, 2)) against the true centre, and which frames are
    found 20 ms after the strike (bool, (n,))."""
    render_video(scene, path)
    tr = track_video(path, scene, TrackerConfig(threaded=False))
    truth = pd.read_csv(path.with_suffix(".truth.csv"))
    n = min(tr.n_frames, len(truth))
    moving = (truth.t.values[:n] > scene.truth.t0 + 0.02) & tr.ok[:n]
    return tr, tr.uv[:n] - np.c_[truth.uc_px.values, truth.vc_px.values][:n], moving


def _moving_errors(scene, path):
    """:func:`_error_stats` of ``scene`` rendered to ``path`` and tracked
    (:func:`_track_errors`)."""
    return _error_stats(*_track_errors(scene, path))


def _error_stats(tr, e, moving):
    """The errors (px, (m, 2)) of the found frames 20 ms after the strike
    (:func:`_track_errors`'s answer), their RMSE and err/se (the RMS of the
    errors over the stated errors)."""
    e = e[moving]
    z = float(np.sqrt(np.mean((e / tr.stderr_px[:len(moving)][moving]) ** 2)))
    return e, float(np.sqrt(np.mean(e ** 2))), z


@pytest.mark.slow
def test_dark_dots_are_not_given_back_to_the_lights_learning(tmp_path):
    # benchmarks/track.py realistic seed 8 shot 8: a white ball with black
    # dots on blue felt, 60 fps, noise 5.4, FFV1, struck at 0.28 s.  The
    # dot at the resting ball's middle was given back to the light's
    # learning (marks_given_back) and the light learnt overhead: every
    # moving frame (-0.07, -0.09) px off, RMSE 0.0868 px (3.5x the bound
    # 0.025), err/se 3.81; given back only when the look learnt with it
    # explains the ball's other pixels (GIVE_BACK_FALSE_RATE's F test; first
    # a diffuse ratio), measured RMSE 0.0353 px, err/se 1.16 (mean error
    # 0.017 px; docs/measurements.md, mark10 and markgate).  Asserted: halfway between
    # on the RMSE and the mean error, err/se under 1.6 (0.4 over the
    # measured, the issue's bound 1.25 plus the spread of 30 frames'
    # err/se, ~0.13 a standard error).
    scene = sample_scenes(9, 8, look="realistic", codec="FFV1")[8]
    scene.render.update(specular=0.0, psf_sigma=0.0, markings="dots", cue=False, balls=[], max_duration=0.8)
    e, rmse, z = _moving_errors(scene, tmp_path / "dots.avi")
    assert len(e) >= 25
    assert rmse < 0.06, rmse
    assert np.hypot(*e.mean(axis=0)) < 0.065, e.mean(axis=0)
    assert z < 1.6, z


@pytest.mark.slow
def test_a_logo_balls_stated_error_is_honest(tmp_path):
    # benchmarks/track.py realistic --mix seed 9 shot 3: a yellow ball with
    # a logo on blue felt, 120 fps, noise 5.9, FFV1, resting 0.2 s then
    # struck; the logo is found and left out in 78 of the 80 moving frames.
    # Measured on main fadee02 and on this rule (docs/measurements.md,
    # markgate): RMSE 0.0077 px, 1.15x the colour bound 0.0067, err/se 1.00
    # (marked frames inside the rim 1.20, at the rim 0.85).  Asserted: the
    # issue's targets, err/se within 0.8-1.25 (80 frames' err/se: ~0.08 a
    # standard error) and RMSE within 1.3x the bound (0.0087 px).
    scene = sample_scenes(4, 9, look="realistic", codec="FFV1")[3]
    scene.render.update(specular=0.0, psf_sigma=0.0, markings="logo", max_duration=0.8)
    e, rmse, z = _moving_errors(scene, tmp_path / "logo.avi")
    assert len(e) >= 70
    assert 0.8 < z < 1.25, z
    assert rmse < 1.3 * 0.0067, rmse


@pytest.mark.slow
def test_a_held_out_logo_ball_stays_near_its_bound(tmp_path):
    # benchmarks/track.py realistic seed 12 shot 18 (a seed no rule was
    # tuned on): a yellow ball with a logo on red felt, 60 fps, noise 6.2,
    # FFV1, 0.8 s; the logo crosses the rim twice.  Measured on main c07f45d
    # (docs/measurements.md, marks3): the 31 found moving frames' RMSE
    # 0.0268 px, 1.34x the colour bound 0.0200 (the benchmark's 6 frames),
    # err/se 1.22, every frame found.  Asserted: RMSE within 1.45x the bound
    # (the measured 1.34x and 8%), err/se within the issue's honest band
    # 0.8-1.25 (the render and FFV1 are deterministic, so no sampling
    # margin applies; measured 1.22), at least 30 frames: a guard against the markings
    # rules getting worse on a shot they were not tuned on (the issue's
    # 1.3x is not met yet).
    scene = sample_scenes(19, 12, look="realistic", codec="FFV1")[18]
    scene.render.update(specular=0.0, psf_sigma=0.0, markings="logo", cue=False, balls=[], max_duration=0.8)
    e, rmse, z = _moving_errors(scene, tmp_path / "logo.avi")
    assert len(e) >= 30
    assert rmse < 1.45 * 0.0200, rmse
    assert 0.8 < z < 1.25, z


@pytest.mark.slow
def test_a_logo_over_the_rim_does_not_run_the_rim_rule_away(tmp_path):
    # benchmarks/track.py realistic seed 8 shot 3: a white ball with a red
    # logo on red felt, 60 fps, noise 3.2, FFV1, 48 frames.  In frame 39 the
    # logo lies over the left rim (17 px, not found inside); the lit
    # sphere's first fit, pulled by it, departs along half the rim, and the
    # rim rule, taking every departing pixel a pass, left out 343 px of the
    # 306-px ball: the frame 0.040 / 0.067 px off (stated 0.038 / 0.070), the
    # shot's RMSE 0.0109 px, 2.38x its colour bound 0.0046 (docs/measurements.md,
    # markgate).  With the strongest group of one sign a pass
    # (RIM_MARK_GROUPS) measured: frame 39 39 px left out, 0.017 px off
    # (stated 0.005 / 0.006), the shot's 35 moving frames RMSE 0.0057 px
    # (1.24x), err/se 1.14, every frame found (docs/measurements.md, rim83).
    # Asserted: frame 39 found within 0.025 px (1.5x the measured; before
    # 0.078), the issue's targets: RMSE within 1.3x the bound, err/se within
    # 0.8-1.25.
    scene = sample_scenes(4, 8, look="realistic", codec="FFV1")[3]
    scene.render.update(specular=0.0, psf_sigma=0.0, markings="logo", cue=False, balls=[], max_duration=0.8)
    tr, e, moving = _track_errors(scene, tmp_path / "logo.avi")
    assert tr.ok[39], tr.status[39]
    assert np.hypot(*e[39]) < 0.025, e[39]
    assert moving.sum() >= 30
    _, rmse, z = _error_stats(tr, e, moving)
    assert rmse < 1.3 * 0.0046, rmse
    assert 0.8 < z < 1.25, z


@pytest.mark.slow
def test_the_felts_ghost_of_the_rest_is_not_flagged_as_something_else(tmp_path):
    # sample_scenes(6, 7, realistic, MJPG)[4] (the test above's shot): the
    # felt learnt around the resting ball holds speckles of it, which depart
    # from the frame by the ball's whole contrast once it has left, and were
    # exported as foreign (TrackResult.foreign: the cue, another ball) on
    # every frame out to 2.67 radii from the rest spot (frames 210-239, 25
    # flagged).  With the ghost (track.tracker.felt_ghost) left out of the
    # flag: 10 flagged, 210-224, the cue approaching, touching and following
    # through within 0.8 radii of the rest spot (fixvis, docs/measurements.md).
    scene = sample_scenes(5, 7, look="realistic", codec="MJPG")[4]
    scene.render["max_duration"] = 0.6
    _, _, tr = track_against_truth(scene, tmp_path / "ghost.avi")
    truth = pd.read_csv((tmp_path / "ghost.avi").with_suffix(".truth.csv"))
    n = min(tr.n_frames, len(truth))
    tuv = np.c_[truth.uc_px.values, truth.vc_px.values][:n]
    away = np.hypot(*(tuv - tuv[0]).T) / tr.radius_px
    assert tr.foreign[:n].any() and away[tr.foreign[:n]].max() < 1.0, np.nonzero(tr.foreign[:n])[0]


# Slow (crash48): 16 s on a quiet machine, 75 s under load (481 frames at
# 480 fps and their render); it cannot be cut: the crash came at frame 354,
# after the strike (frame 170).
@pytest.mark.slow
def test_a_blob_narrower_than_the_ball_is_not_a_window_of_negative_size(tmp_path):
    # benchmarks/accuracy.py --look realistic --preset case4 --codec MJPG
    # --max-seconds 1 seed 48 shot 5 (a red ball with a logo on red felt,
    # the cue, 480 fps): at frame 354 the blob above a quarter of the
    # contrast was narrower than the ball, the longest streak the exposure
    # allows came out -14.7 px, the fit's window a negative half-width, and
    # its empty felt raised "negative dimensions not allowed" out of
    # track_video (and killed the benchmark's worker pool).  Now a streak
    # is never negative: the frame is fitted in the ball's own window and
    # given a status.  Measured: before, ValueError; after, 481 frames, 44
    # found (9.2% of those on open cloth, 1 more than a quarter radius off:
    # red on red, the cue and the logo), frame 354 "fit failed".
    scene = sample_scenes(6, 48, preset="case4", camera="topdown", look="realistic")[5]
    assert (scene.render["ball_name"], scene.render["felt_name"]) == ("red", "red")
    scene.render.update(max_duration=1.0, codec="MJPG")
    path = tmp_path / "shot5.avi"
    render_video(scene, path)
    tr = track_video(path, scene, TrackerConfig(threaded=False))
    assert tr.n_frames == 481
    assert tr.ok.any()
    # the frame that crashed is refused with a status (re-read: the earlier
    # ok-versus-status checks held by construction, track.video builds ok
    # from status)
    assert tr.status[354] != OK


@pytest.mark.slow
def test_a_still_h264_rest_is_not_flagged_foreign_and_the_cue_still_is(tmp_path):
    # sample_scenes(1, 49, realistic, H264)[0] cut to 0.6 s: a white ball
    # with dots on green, no cue, no other ball, 60 fps, noise 7.1 per
    # channel, struck at frame 26.  H.264 keeps the still felt's blocks, so
    # the noise read between two frames is 0.26 levels; the luma-blind
    # channel's one chroma sample (4 px of 4:2:0) beside the ball, 1.0-1.05
    # times the threshold, flagged every frame of the rest as foreign
    # (26 of 26), and a cue-flagged frame is never the rest: v0 was refused
    # (held39).  With foreign_seen's SEEN_MIN_BLOCKS and SEEN_SPREAD_SIGMAS
    # none of them (docs/measurements.md, foreign).  sample_scenes(10, 49,
    # realistic, H264)[9] (blue on green, the cue, luma-blind too): the
    # cue's frames 20-22 (groups of 8-12 px) flagged as before.
    scene = sample_scenes(1, 49, look="realistic", codec="H264")[0]
    scene.render["max_duration"] = 0.6
    path = tmp_path / "still.mp4"
    render_video(scene, path)
    tr = track_video(path, scene, TrackerConfig(threaded=False))
    k0 = int(np.floor(scene.truth.t0 * scene.camera.fps))
    assert tr.ok[:k0].all()
    assert not tr.foreign[:k0].any(), np.nonzero(tr.foreign[:k0])[0]
    scene = sample_scenes(10, 49, look="realistic", codec="H264")[9]
    scene.render["max_duration"] = 0.6
    path = tmp_path / "cue.mp4"
    render_video(scene, path)
    tr = track_video(path, scene, TrackerConfig(threaded=False))
    fr = FrameRenderer(scene)
    near = fr.cue_tip(fr.truth.t)[:tr.n_frames] < scene.physics.R
    assert tr.foreign[:tr.n_frames][near].sum() >= 3, np.nonzero(tr.foreign)[0]


@pytest.mark.slow
def test_the_cues_joint_over_the_rail_is_not_first_found_as_the_ball(tmp_path):
    # benchmarks/track.py realistic --mix seed 5 shot 9 (FFV1, 0.6 s): a red
    # ball on red felt with lens blur (PSF 0.858 px, noise 4.0, 120 fps), two
    # balls at rest and a cue.  The channel is learnt from the cue's motion
    # (tan against red); the ball is ~0 in it (box score 3.4 against the
    # threshold 26) and the cue's joint on the rail, its centre 0.75 radii
    # past the cushion's line, was found as the ball in 8 of 73 frames,
    # 255-314 px off with stated errors 0.09-0.23 px (docs/measurements.md,
    # red9).  The ball is first found on the playing surface only
    # (BallTracker's ``surface``): measured 0 of 73 found, the track's error
    # saying no ball was found.  Finding the ball here needs a channel
    # learnt from its own motion, not the cue's: not done.
    from benchmarks.track import realistic_scene

    scene, look = realistic_scene(9, 5, 0.6, True)
    assert look == "blur" and scene.render["cue"] and len(scene.render["balls"]) == 2
    found, err, tr = track_against_truth(scene, tmp_path / "joint.avi")
    assert not (err >= MAX_ERR_RADII).any(), f"{(err >= MAX_ERR_RADII).sum()} found centres up to {err.max():.1f} radii off"
    if not err.size:  # failure is an answer, with its reason
        assert "no ball found" in tr.error
