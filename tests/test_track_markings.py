"""Markings on the ball (dots, a logo) left out of the fit (track.tracker.marking_pixels).

The decision on simulated ball patches (the shaded model's own look, and the
same smeared as a codec smears it, noise 3, 200 patches each): it must not
fire on an unmarked ball (measured: 0 of 300 each), and on a ball with two
dark dots it must fire and give back the centre an unmarked ball gets
(measured: the shaded fit with the dots 0.22 px off at most, RMS 0.09;
without them 0.019 and 0.008, as an unmarked ball's 0.020 and 0.007).  A
rendered marked ball, end to end, is in test_track_realistic.py (slow).
"""

import cv2
import numpy as np
import pytest

from cuespin.render.draw import disc_coverage
from cuespin.render.video import encode_frames
from cuespin.track.model import fit_disc, streak_model
from cuespin.track.reader import FrameSource, probe
from cuespin.track.tracker import marking_pixels

R, FELT, BALL, NOISE = 10.0, 80.0, 200.0, 3.0
HALF = int(np.ceil(R + 3))
N = 200


def patch(rng, kind, dots=0):
    """A shaded ball's patch (grey levels), its felt, top-left pixel and true
    centre; ``dots`` dark dots of radius 2 px within 0.7 radii of the centre."""
    c = np.array([50.0, 40.0]) + rng.uniform(-0.5, 0.5, 2)
    u0, v0 = int(round(c[0])) - HALF, int(round(c[1])) - HALF
    n = 2 * HALF + 1
    felt = np.full((n, n), FELT)
    img, _ = streak_model(c, np.zeros(2), BALL, felt, R, u0, v0, np.zeros(1), (-40.0, -40.0, -30.0))
    img = img + felt
    if kind == "smeared":  # a codec's smear of the edge (chroma at half resolution)
        img = cv2.GaussianBlur(img, (0, 0), 0.7)
    for _ in range(dots):
        a, d = rng.uniform(0, 2 * np.pi), rng.uniform(0, 0.7 * R)
        cov = disc_coverage(c[0] + d * np.cos(a), c[1] + d * np.sin(a), 2.0, u0, v0, n, n)
        img = img * (1 - cov) + 30.0 * cov
    img = np.clip(np.rint(img + NOISE * rng.standard_normal(img.shape)), 0, 255)
    return img, felt, u0, v0, c


def fits(kind, dots, seed):
    """Per patch: whether markings were found, the shaded fit's centre error
    (px) and that of its refit without them (NaN when none were found)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(N):
        img, felt, u0, v0, c = patch(rng, kind, dots)
        f = fit_disc(img, felt, u0, v0, c + rng.normal(0.0, 0.05, 2), R, BALL, shade=True)
        assert f, f.reason
        m = marking_pixels(img, felt, u0, v0, f.c, f.b, R, R, NOISE, BALL - FELT)
        e1 = np.nan
        if m is not None:
            g = fit_disc(img, felt, u0, v0, f.c, R, f.G, shade=True, valid=~m)
            assert g, g.reason
            e1 = np.hypot(*(g.c - c))
        out.append((m is not None, np.hypot(*(f.c - c)), e1))
    return np.array(out)


@pytest.mark.parametrize("kind", ["shaded", "smeared"])
def test_markings_are_not_found_on_an_unmarked_ball(kind):
    # Measured 0 of 300 for each kind; one in 200 allowed.
    assert fits(kind, 0, seed=1)[:, 0].sum() <= 1


def test_dots_are_left_out_and_the_centre_comes_back():
    out = fits("shaded", 2, seed=2)
    assert out[:, 0].all()
    before, after = out[:, 1], out[:, 2]
    # The dots pull the fit (measured max 0.22 px, RMS 0.09) ...
    assert np.sqrt(np.mean(before**2)) > 0.05
    # ... and without them it is an unmarked ball's (max 0.020, RMS 0.007):
    # twice those.
    assert after.max() < 0.04 and np.sqrt(np.mean(after**2)) < 0.015


def mjpg_still(tmp_path, markings: str, specular: float):
    """A yellow ball with a highlight at rest on green felt (a realistic
    render, 240 fps, noise 1.1) and the felt (the same render once the ball
    has left), both through OpenCV's MJPG writer and back, the true centre
    and radius (px)."""
    from cuespin.data_gen.sampler import sample_scenes
    from cuespin.render.draw import FrameRenderer
    from cuespin.render.look import BALL_COLOURS, FELT_COLOURS

    scene = sample_scenes(1, 0, look="realistic", codec="MJPG")[0]
    scene.render.update(ball_colour=list(BALL_COLOURS["yellow"]), felt_colour=list(FELT_COLOURS["green"]),
                        specular=specular, markings=markings, mark_colour=[25, 25, 25], cue=False, balls=[],
                        max_duration=0.8, psf_sigma=0.0)
    fr = FrameRenderer(scene)
    rng = np.random.default_rng(0)
    still, gone = fr.render(0, rng), fr.render(fr.n_frames - 1, rng)
    path = tmp_path / f"{markings}_{specular}.avi"
    encode_frames([still, gone], path, "MJPG", scene.camera.fps, still.shape[1::-1])
    coded = list(FrameSource(path, probe(path)))
    c = scene.camera.to_pixels(np.array([scene.truth.x0[:2]]))[0]
    return coded[0], coded[1], c, scene.physics.R * scene.camera.px_per_m(c), scene


@pytest.mark.parametrize("markings, specular", [("none", 0.0), ("none", 0.6), ("dots", 0.0), ("dots", 0.6)])
def test_mjpg_ball_flagged_only_with_markings(tmp_path, markings, specular):
    # On MJPG the look-ahead's contrast can be a small fraction of the
    # ball's (benchmarks/track.py realistic seed 0 shot 12, a yellow ball
    # with a highlight on green felt at 480 fps: 8.8 in the white-free
    # channel, where the ball's fitted level stands ~140 above the felt;
    # noise read as 0.32).  The rule at 0.35 of it took the highlighted
    # plain ball here for markings (435 of its 460 pixels) and found no dots
    # on the dotted one (its refit without most of the ball was rejected).
    # Scaled by the fit's own level (measured): a plain ball is left whole,
    # a highlighted one loses its highlight's chroma block (24 px), black
    # dots are found (45 and 48 px with their one-pixel growth).
    from cuespin.render.look import BALL_COLOURS, FELT_COLOURS
    from cuespin.track.background import Background
    from cuespin.track.colour import FELT_LEVEL, Projection, white_free
    from cuespin.track.tracker import OK, BallTracker, TrackerConfig
    from cuespin.track.video import search_mask

    coded, gone, c, r, scene = mjpg_still(tmp_path, markings, specular)
    d = np.array(BALL_COLOURS["yellow"], float) - np.array(FELT_COLOURS["green"], float)
    wts = white_free(d, np.eye(3))  # the white-free channel shot 12 was tracked in: R - B, much as here
    wts = (wts / np.abs(wts).max()).astype(np.float32)
    felt_bgr = gone.reshape(-1, 3).mean(axis=0)
    proj = Projection(wts, float(FELT_LEVEL - wts @ felt_bgr))
    bg = Background(image=proj(gone), sigma=0.32, polarity=int(np.sign(wts @ d)), contrast=8.8, n_samples=9,
                    path_pixels=0, weak_samples=np.zeros(9, bool))
    mask = search_mask(scene.camera, scene.table, scene.physics.R, coded.shape[:2])
    T = BallTracker(bg, r, 0.0, TrackerConfig(threaded=False, look="shaded", sphere=False), projection=proj,
                    search_mask=mask)
    obs = T.step(0, coded)
    assert obs.status == OK and np.hypot(*(obs.uv - c)) < 0.25 * r
    marks = T.last_fit.marks
    if markings == "dots":
        assert marks is not None and marks.sum() >= 30
    elif specular == 0.0:
        assert marks is None
    else:  # the highlight at most: under a tenth of the ball
        assert marks is None or marks.sum() < 0.1 * np.pi * r * r


def test_a_smeared_dot_is_left_out_along_the_blur():
    # A shaded ball smeared over 6.3 px (24 nodes) with a dark dot (radius
    # 2.5 px, 0.4-0.7 radii off-centre) smeared with it, 100 patches at
    # noise 3, fitted with the blur: with the dot in, the centre is 0.56 px
    # off (RMS; 99 of the fits converge); left out, its faint ends along the streak pulled the
    # refit to RMS 0.0263 (max 0.074) when grown by one pixel only, and
    # 0.0206 (max 0.053) grown along the blur inside the rim (smear_kernel), against the
    # unmarked ball's 0.0180 (max 0.045): tolerances between the two.
    from cuespin.track.model import blur_nodes

    b = np.array([6.0, 2.0])
    taus = blur_nodes(24.0)
    rng = np.random.default_rng(3)
    half = int(np.ceil(R + 0.5 * np.hypot(*b) + 3))
    n = 2 * half + 1
    felt = np.full((n, n), FELT)
    err = []
    for _ in range(100):
        c = np.array([60.0, 50.0]) + rng.uniform(-0.5, 0.5, 2)
        u0, v0 = int(round(c[0])) - half, int(round(c[1])) - half
        img, _ = streak_model(c, b, BALL, felt, R, u0, v0, taus, (-40.0, -40.0, -30.0))
        a, d = rng.uniform(0, 2 * np.pi), rng.uniform(0.4, 0.7) * R
        dot = np.mean([disc_coverage(c[0] + t * b[0] + d * np.cos(a), c[1] + t * b[1] + d * np.sin(a), 2.5,
                                     u0, v0, n, n) for t in taus], axis=0)
        img = np.clip(np.rint(img + felt + dot * (30.0 - BALL) + NOISE * rng.standard_normal(img.shape)), 0, 255)
        f = fit_disc(img, felt, u0, v0, c + rng.normal(0, 0.05, 2), R, BALL, b0=b, fit_blur=True, shade=True)
        if not f:  # the dot in, the first fit may not converge (measured: 1 of 100)
            continue
        m = marking_pixels(img, felt, u0, v0, f.c, f.b, R, R, NOISE, BALL - FELT)
        assert m is not None
        g = fit_disc(img, felt, u0, v0, f.c, R, f.G, b0=f.b, fit_blur=True, shade=True, valid=~m)
        assert g, g.reason
        err.append(np.hypot(*(g.c - c)))
    err = np.array(err)
    assert len(err) >= 98
    assert np.sqrt(np.mean(err**2)) < 0.024 and err.max() < 0.06, (np.sqrt(np.mean(err**2)), err.max())


def known_pixels_bound2(c, felt, u0, v0, r, shade, clear) -> float:
    """The Cramer-Rao bound's centre variance (px^2, both axes summed) of a
    lit sphere whose markings' pixels are known (only ``clear`` used), at
    noise 1.7, with its level and look coefficients as nuisances."""
    _, J = streak_model(c, np.zeros(2), 60.0, felt, r, u0, v0, np.zeros(1), shade, blur_cols=False)
    J = J[clear.ravel()][:, [0, 1, 4, 5, 6, 7]]
    return 1.7 ** 2 * np.trace(np.linalg.inv(J.T @ J)[:2, :2])


def rms_px(errors) -> float:
    """RMS of 2-D centre errors (px)."""
    return float(np.sqrt(np.mean(np.sum(np.square(errors), 1))))


def stand_in_tracker(sigma: float):
    """What BallTracker's rim rules read of a tracker: one-pixel blocks, the
    frames' noise ``sigma`` (levels), and its fits (no felt ghost here)."""
    from types import SimpleNamespace
    return SimpleNamespace(block=1, bg=SimpleNamespace(sigma=sigma), _fit_disc=fit_disc)


def lit_ball(rng):
    """The strongly shaded ball both marked balls below carry (the lit
    sphere's look, ambient 60, diffuse 200, light at 0.92 rad: realistic
    seed 0 shot 18's), radius 12.2 px, on a textured felt, noise-free:
    (the image, felt, top-left pixel, true centre, radius, window side, look)."""
    from cuespin.track.model import SphereLook
    r, n = 12.2, 33
    look = SphereLook(float(rng.uniform(0, 2 * np.pi)), 0.92, 10.0)
    c = np.array([384.0, 350.0]) + rng.uniform(0, 1, 2)
    u0, v0 = int(round(c[0])) - n // 2, int(round(c[1])) - n // 2
    felt = 90.0 + rng.normal(0, 2, (n, n))
    img = felt + streak_model(c, np.zeros(2), 60.0, felt, r, u0, v0, np.zeros(1),
                              np.r_[200.0, 0.0, 0.0, look.geometry()])[0]
    return img, felt, u0, v0, c, r, n, look


def lit_marked_ball(rng, inside=(5.0, 7.0)):
    """A strongly shaded ball (the lit sphere's look, ambient 60, diffuse 200,
    light at 0.92 rad: realistic seed 0 shot 18's) of radius 12.2 px on a
    textured felt, dark dots inside at the distances ``inside`` (px; two by
    default) and one at the rim (centred 0.7 px
    inside it, where the markings rule does not look), noise 1.7: (the
    frame, felt, top-left pixel, true centre, look, the pixels no dot
    touches)."""
    img, felt, u0, v0, c, r, n, look = lit_ball(rng)
    clear = np.ones((n, n), bool)
    dist = (*inside, r - 0.7)
    a = rng.uniform(0, 2 * np.pi, len(dist))
    for ang, d in zip(a, dist):
        cov = disc_coverage(c[0] + d * np.cos(ang), c[1] + d * np.sin(ang), 2.0, u0, v0, n, n)
        img = img * (1 - cov) + 30.0 * cov
        clear &= cov == 0
    img = np.clip(np.rint(img + 1.7 * rng.standard_normal(img.shape)), 0, 255)
    return img, felt, u0, v0, c, r, look, clear


def test_a_dot_at_the_rim_is_left_out_against_the_lit_sphere():
    # The tracker's refits of a marked frame once the lit sphere is learnt:
    # the quadratic look without the markings the rule finds inside the rim,
    # then the lit sphere from there on the same pixels, then without the
    # dot at the rim (BallTracker._rim_unmarked).  Measured (seed 2, 30
    # patches): without the rim's rule RMS error 0.152 px, 28x the bound of
    # a fit that knows which pixels the dots touch; with it 0.0054, 0.99x.
    # Asserted: within 1.5x the measured ratio, and the rim dot's pull
    # present without the rule.  Every lit sphere's fit states an error:
    # Gauss-Newton cycles on the pixel-centred look's kinks in some of them
    # (model._kinked_minimum).
    from cuespin.track.tracker import BallTracker
    rng = np.random.default_rng(2)
    T = stand_in_tracker(1.7)
    err_rim, err_in, bound = [], [], []
    for _ in range(30):
        img, felt, u0, v0, c, r, look, clear = lit_marked_ball(rng)
        T.shade = look
        f = fit_disc(img, felt, u0, v0, c + [0.3, -0.2], r, 150.0, shade=True)
        assert f, f.reason
        m = marking_pixels(img, felt, u0, v0, f.c, f.b, r, r, 1.7, 200.0)
        assert m is not None
        q = fit_disc(img, felt, u0, v0, f.c, r, f.G, shade=True, valid=~m)
        g = fit_disc(img, felt, u0, v0, q.c, r, q.G, shade=look, valid=~m)
        assert g and g.stated, g.reason
        h, _ = BallTracker._rim_unmarked(T, img, felt, u0, v0, g, r, False, None, m, None)
        assert h.stated
        err_in.append(g.c - c)
        err_rim.append(h.c - c)
        bound.append(known_pixels_bound2(c, felt, u0, v0, r, g.shade, clear))
    crb, rmse_rim, rmse_in = np.sqrt(np.mean(bound)), rms_px(err_rim), rms_px(err_in)
    assert rmse_rim / crb < 1.5 * 0.99
    assert rmse_in > 10 * rmse_rim


def test_a_marked_balls_frame_without_markings_inside_loses_its_rim_dot():
    # Rule MARKED_BALL_FRAMES: once the rule inside found markings in 8
    # frames, a frame where it finds none still gets the lit sphere's rule
    # at the rim (BallTracker._rim_unmarked from no markings, as
    # BallTracker._refine calls it).  One dot at the rim, none inside.
    # Measured (seed 2, 30 patches, docs/measurements.md marks8): the lit
    # sphere's fit with the dot RMS error 0.167 px, 31x the bound of a fit
    # that knows the dot's pixels; after the rule 0.0055 px, 1.02x.
    # Asserted: within 1.5x the measured ratio, and the dot's pull present
    # without the rule.  The gate itself (the count of marked frames) is
    # measured on realistic seed 0 shot 3 (slow).
    from cuespin.track.tracker import BallTracker
    rng = np.random.default_rng(2)
    T = stand_in_tracker(1.7)
    err_with, err_without, bound = [], [], []
    for _ in range(30):
        img, felt, u0, v0, c, r, look, clear = lit_marked_ball(rng, inside=())
        T.shade = look
        g = fit_disc(img, felt, u0, v0, c + [0.3, -0.2], r, 150.0, shade=look)
        assert g and g.stated, g.reason
        h, _ = BallTracker._rim_unmarked(T, img, felt, u0, v0, g, r, False, None, None, None)
        assert h.stated
        err_with.append(g.c - c)
        err_without.append(h.c - c)
        bound.append(known_pixels_bound2(c, felt, u0, v0, r, g.shade, clear))
    crb, rmse_without, rmse_with = np.sqrt(np.mean(bound)), rms_px(err_without), rms_px(err_with)
    assert rmse_without / crb < 1.5 * 1.02
    assert rmse_with > 10 * rmse_without


def test_faint_rim_dots_are_found_on_a_still_balls_mean_window():
    # tracker.rim_left_out on the lit sphere's voting frames: a still ball's
    # 12 frames, two faint dots (-8 levels at full cover) at the rim, noise
    # 1.7.  Frame by frame the rule takes 23-52% of the dots' pixels (a dot
    # departs under its 5 sigmas); on the frames' mean window (the window
    # learn_sphere fits) all of them and nothing beyond the dots grown by
    # one (seeds 0-3, measured, /tmp/marks8/t9.py).  Realistic seed 0 shot
    # 13: the learnt elevation 1.372 -> 1.329 rad (the renderer's 1.318).
    from cuespin.track.model import SphereLook
    from cuespin.track.sphere import Sample
    from cuespin.track.tracker import rim_left_out
    for seed in range(2):
        rng = np.random.default_rng(seed)
        r, n = 12.2, 33
        look = SphereLook(float(rng.uniform(0, 2 * np.pi)), 1.3, 10.0)
        c = np.array([384.0, 350.0]) + rng.uniform(0, 1, 2)
        u0, v0 = int(round(c[0])) - n // 2, int(round(c[1])) - n // 2
        felt = 90.0 + rng.normal(0, 2, (n, n))
        img = felt + streak_model(c, np.zeros(2), 60.0, felt, r, u0, v0, np.zeros(1),
                                  np.r_[200.0, 0.0, 0.0, look.geometry()])[0]
        dot = np.zeros((n, n))
        for ang in rng.uniform(0, 2 * np.pi, 2):
            dot += disc_coverage(c[0] + (r - 0.7) * np.cos(ang), c[1] + (r - 0.7) * np.sin(ang), 2.0, u0, v0, n, n)
        img = img - 8.0 * dot
        frames = [Sample(np.clip(np.rint(img + 1.7 * rng.standard_normal(img.shape)), 0, 255), felt, u0, v0, c,
                         np.zeros(2), 60.0, False, np.zeros(3), None) for _ in range(12)]
        rim = rim_left_out(frames, look, [True] * 12, r)
        assert rim is not None
        out = ~rim[0].valid
        assert all(np.array_equal(~s.valid, out) for s in rim)  # the same pixels out in every frame
        core = dot > 0.5
        grown = cv2.dilate((dot > 0).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        assert (out & core).sum() == core.sum()
        assert not (out & ~grown).any()


def logo_at_the_rim(rng, tilt=1.25, depth=8.0, noise=2.5):
    """lit_marked_ball's strongly shaded ball with the renderer's logo
    (render.look.mark_mask, "logo") turned ``tilt`` rad from the view
    towards a random side, so that its large disc shows as a crescent at
    the rim, ``depth`` levels darker (realistic seed 0 shot 3's: -5..-12
    at noise 2.5, under the rim's one-pixel rule): (the frame, felt,
    top-left pixel, true centre, radius, look, the pixels the logo does not
    touch)."""
    from cuespin.render import look as lk
    img, felt, u0, v0, c, r, n, look = lit_ball(rng)
    # R takes the body's z (the logo's centre, render.look.marks) to d.
    az = rng.uniform(0, 2 * np.pi)
    d = np.array([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])
    k = np.cross([0.0, 0.0, 1.0], d)
    s = np.linalg.norm(k)
    k /= s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = np.eye(3) + s * K + (1 - d[2]) * K @ K
    X, Y = np.meshgrid((np.arange(u0, u0 + n) - c[0]) / r, (np.arange(v0, v0 + n) - c[1]) / r)
    rho2 = X * X + Y * Y
    normals = np.stack([X, Y, np.sqrt(np.maximum(1 - rho2, 0))], -1)
    m = lk.mark_mask(normals @ R, "logo", r) * (rho2 < 1)  # body normals R^T n
    img = np.clip(np.rint(img - depth * m + noise * rng.standard_normal(img.shape)), 0, 255)
    return img, felt, u0, v0, c, r, look, m == 0


def test_a_logos_faint_crescent_at_the_rim_is_left_out():
    # tracker.RIM_MARK_BOX: a logo turned over the rim, each pixel under the
    # rim's one-pixel rule, its 3 x 3 means over it; BallTracker._rim_unmarked
    # from no markings (a marked ball's frame, MARKED_BALL_FRAMES).  Measured
    # (30 patches, noise 2.5, /tmp/marks9/t1.py): RMS error over the bound
    # of a fit that knows the logo's pixels, without -> with the rule, seed
    # 0 2.39x -> 1.12x, seed 1 2.68 -> 1.44, seed 2 2.24 -> 1.06.  Asserted
    # on seed 0: under the largest of the three, and the logo's pull at
    # least 1.5x what is left (seed 0: 2.1x; seeds 1-2 1.9x, 2.1x).
    from cuespin.track.tracker import BallTracker
    rng = np.random.default_rng(0)
    noise = 2.5
    T = stand_in_tracker(noise)
    err_with, err_without, bound = [], [], []
    for _ in range(30):
        img, felt, u0, v0, c, r, look, clear = logo_at_the_rim(rng, noise=noise)
        T.shade = look
        g = fit_disc(img, felt, u0, v0, c + [0.3, -0.2], r, 150.0, shade=look)
        assert g and g.stated, g.reason
        h, _ = BallTracker._rim_unmarked(T, img, felt, u0, v0, g, r, False, None, None, None)
        err_with.append(g.c - c)
        err_without.append(h.c - c)
        bound.append(known_pixels_bound2(c, felt, u0, v0, r, g.shade, clear) * (noise / 1.7) ** 2)
    crb, rmse_without, rmse_with = np.sqrt(np.mean(bound)), rms_px(err_without), rms_px(err_with)
    assert rmse_without / crb < 1.44
    assert rmse_with > 1.5 * rmse_without


@pytest.mark.parametrize("mirrored, given_back", [(False, True), (True, False)])
def test_markings_are_given_back_only_to_a_look_that_keeps_the_balls_light(mirrored, given_back):
    # tracker.GIVE_BACK_FALSE_RATE: a still ball's 12 frames (lit_ball's
    # look, noise 5), a faint spot (10 levels, under the give-back rule's 5
    # sigmas) at its middle found as a marking in every frame.  Against a
    # look learnt with it in that explains the ball's other pixels as the
    # look learnt without it does (the same look: F 0, p 1) it is given
    # back; against one that holds it only with its light turned over (the
    # light from the other side, as realistic seed 8 shot 8's look bent by a
    # dark dot) the F test refuses it (p far under the stated 0.001) and it
    # stays out.  Without the check (``without`` None) both are given back.
    from cuespin.track.model import SphereLook
    from cuespin.track.sphere import Sample
    from cuespin.track.tracker import marks_given_back
    rng = np.random.default_rng(0)
    img, felt, u0, v0, c, r, n, look = lit_ball(rng)
    spot = disc_coverage(c[0], c[1], 1.5, u0, v0, n, n)
    mark = cv2.dilate((spot > 0).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    frames = [Sample(np.clip(np.rint(img - 10.0 * spot + 5.0 * rng.standard_normal(img.shape)), 0, 255), felt,
                     u0, v0, c, np.zeros(2), 60.0, False, np.zeros(3), ~mark) for _ in range(12)]
    marks, foreign = [mark] * 12, [None] * 12
    lit = SphereLook(look.azimuth + np.pi, look.elevation, look.shininess) if mirrored else look
    assert (marks_given_back(frames, lit, marks, foreign, r, 5.0, without=look) is not None) == given_back
    assert marks_given_back(frames, lit, marks, foreign, r, 5.0) is not None
