"""The lit sphere's look (track.model.SphereLook, track.sphere): its geometry
learnt from still frames, and the centre it gives on a rendered shaded,
highlighted ball."""

from functools import partial

import numpy as np
import pandas as pd
import pytest

from cuespin.track.model import SphereLook, fit_disc, streak_model
from cuespin.track.sphere import Sample, learn_sphere, relearn_both_sides
from cuespin.track.tracker import BallTracker, TrackerConfig, marking_pixels

H = W = 37
U0, V0, R_PX = 500, 283, 14.3
# The still ball the fast tests draw: lit from azimuth 2.2 at 1.1 rad with a
# highlight of shininess 40 (level 150, diffuse 60, highlight 120).
TRUTH = SphereLook(2.2, 1.1, 40.0)
GEO = np.r_[60.0, 120.0, 0.0, TRUTH.geometry()]
C_TRUE = np.array([518.31, 301.72])


def lit_ball(seed: int, r: float = R_PX, shape=(H, W), c=C_TRUE):
    """The generator after the felt's draw, a felt (90 +- 2) and the lit
    ball's departure from it, radius ``r`` px, centre ``c``."""
    rng = np.random.default_rng(seed)
    felt = 90.0 + rng.normal(0, 2, shape)
    return rng, felt, streak_model(c, np.zeros(2), 150.0, felt, r, U0, V0, np.zeros(1), GEO)[0]


def still_samples(rng, clean, felt, n: int = 12):
    """``n`` noisy frames (noise 3) of the still ball ``clean`` fitted with
    the quadratic look, as the tracker hands them to the lit sphere's
    learning: (the Samples, the last fit, its frame)."""
    samples = []
    for _ in range(n):
        img = clean + rng.normal(0, 3.0, clean.shape)
        f = fit_disc(img, felt, U0, V0, C_TRUE + [0.3, -0.2], R_PX, 170.0, shade=True)
        assert f
        samples.append(Sample(img, felt, U0, V0, f.c, f.b, f.G, False, f.shade, None))
    return samples, f, img


def render_and_track(scene, path):
    """Render ``scene`` to ``path`` and track it as the command does:
    (the result, the truth sidecar's rows the track covers, their true
    centres (px))."""
    from cuespin.render import render_video
    from cuespin.track.video import track_video

    render_video(scene, path)
    res = track_video(path, scene, TrackerConfig(threaded=False))
    truth = pd.read_csv(path.with_suffix(".truth.csv"))
    truth = truth.iloc[:min(res.n_frames, len(truth))]
    return res, truth, np.c_[truth.uc_px.values, truth.vc_px.values]


def test_learnt_geometry_pins_the_centre():
    # Twelve noisy frames of a still ball (noise 3) lit from azimuth 2.2 at
    # 1.1 rad with a highlight of shininess 40: the geometry is learnt from
    # the quadratic look's fits, and the sphere's fit of one frame then
    # lands on the true centre within 4 of its stated errors (the
    # quadratic look's is pulled by its lit side: 5.1 of them, measured).
    rng, felt, ball = lit_ball(11)
    truth, c = TRUTH, C_TRUE
    clean = felt + ball
    samples, f, img = still_samples(rng, clean, felt)
    quad = np.hypot(*(f.c - c)) / f.stderr.max()
    look, _ = learn_sphere(samples, R_PX)
    assert abs(np.angle(np.exp(1j * (look.azimuth - truth.azimuth)))) < 0.1
    assert abs(look.elevation - truth.elevation) < 0.1
    g = fit_disc(img, felt, U0, V0, c + [0.3, -0.2], R_PX, 170.0, shade=look)
    assert g and np.all(np.abs(g.c - c) <= 4 * g.stderr)
    assert quad > 3


def test_learnt_again_against_the_clean_felt():
    # The sampled background at a rest spot may keep an imprint of the
    # resting ball (here 0.15 of it, 4 px aside): the geometry learnt
    # against it is off (azimuth 0.013 rad, measured) and moves the centre
    # of a fit against the clean felt by 1.4 of its stated errors; learnt
    # again from there against the clean felt (start=, as
    # BallTracker.relearn_sphere does), azimuth and elevation come within
    # 0.0008 and 0.0013 rad of the truth (measured) and the centre within
    # 0.3 of them.
    rng, felt, ball = lit_ball(11)
    truth, c = TRUTH, C_TRUE
    imprinted = felt + 0.15 * streak_model(c + [4.0, 0.0], np.zeros(2), 150.0, felt, R_PX, U0, V0, np.zeros(1),
                                           GEO)[0]
    samples = []
    for _ in range(12):
        img = felt + ball + rng.normal(0, 3.0, ball.shape)
        f = fit_disc(img, imprinted, U0, V0, c + [0.3, -0.2], R_PX, 170.0, shade=True)
        assert f
        samples.append(Sample(img, imprinted, U0, V0, f.c, f.b, f.G, False, f.shade, None))
    first, _ = learn_sphere(samples, R_PX)
    again, _ = learn_sphere([s._replace(felt=felt) for s in samples], R_PX, start=first)
    assert abs(again.azimuth - truth.azimuth) < 0.005 < abs(first.azimuth - truth.azimuth)
    assert abs(again.elevation - truth.elevation) < 0.005
    g = fit_disc(img, felt, U0, V0, c + [0.3, -0.2], R_PX, 170.0, shade=again)
    assert g and np.all(np.abs(g.c - c) <= g.stderr)


def test_markings_stay_out_of_the_lights_learning():
    # The tracker's own hand-over (_keep_for_sphere, _learn_sphere): twelve
    # still frames of a lit ball with two dark dots, each fitted with the
    # dots left out as the tracker does.  With the dots back in the
    # learning the elevation came out 1.283 for 1.10 and the refitted
    # frames 0.044 px off (RMS, about 8 of their errors; review, seed 5);
    # with them out, 1.099 and 0.0067 px.  Asserted: elevation within 0.05
    # rad and the refitted frames within 2x the fixed code's RMS.
    from types import SimpleNamespace

    from cuespin.render.draw import disc_coverage
    rng, felt, ball = lit_ball(5)
    truth, c = TRUTH, C_TRUE
    clean = felt + ball
    for a, d in ((0.5, 6.0), (2.8, 8.0)):
        cov = disc_coverage(c[0] + d * np.cos(a), c[1] + d * np.sin(a), 2.5, U0, V0, H, W)
        clean = clean * (1 - cov) + 30.0 * cov
    T = SimpleNamespace(cfg=TrackerConfig(), shade=None, _look_fits=[], r=R_PX, outline=None, block=1,
                        bg=SimpleNamespace(sigma=3.0),  # the noise the frames are drawn with
                        _fit_disc=fit_disc)  # no felt ghost: the felt is the frames' own
    T._rim_unmarked = partial(BallTracker._rim_unmarked, T)  # the voting frames' rim markings (found11)
    fits = []
    for _ in range(12):
        img = np.clip(np.rint(clean + rng.normal(0, 3.0, clean.shape)), 0, 255)
        f0 = fit_disc(img, felt, U0, V0, c + [0.2, -0.1], R_PX, 170.0, shade=True)
        m = marking_pixels(img, felt, U0, V0, f0.c, f0.b, R_PX, R_PX, 3.0, 100.0)
        assert m is not None
        f = fit_disc(img, felt, U0, V0, f0.c, R_PX, f0.G, shade=True, valid=~m)
        assert f
        fits.append(f)
        lf = SimpleNamespace(marks=m, foreign=None, c=f.c.copy())
        BallTracker._keep_for_sphere(T, f, img, felt, U0, V0, False, None, lf)
    BallTracker._learn_sphere(T)
    assert isinstance(T.shade, SphereLook)
    assert abs(T.shade.elevation - truth.elevation) < 0.05
    err = np.array([np.hypot(*(f.c - c)) for f in fits])
    assert np.sqrt(np.mean(err ** 2)) < 2 * 0.0067


def test_lens_blur_learnt_with_the_light():
    # The still ball seen through a lens: its departure from the felt
    # convolved with the renderer's Gaussian PSF (render.draw.gaussian, as
    # FrameRenderer draws it), sigma 0.8 px, noise 3.  Learnt from twelve
    # frames' quadratic fits, the PSF came out 0.803 px (measured, seed 11;
    # sigma 0.5 and 1.0: 0.50 and 0.996, seeds 3, 4), and over 40 frames the
    # sphere's fits with it were 0.0089 px off (RMS; err/se 0.97), with the
    # same light but no PSF 0.050 px (err/se 2.5: a bias of 0.07 px).
    # Asserted: the PSF within 0.05 px, the RMS within 2x the measured and
    # err/se in the issue's 0.8-1.25 widened by 40 frames' spread (+-0.15).
    from cuespin.render.draw import gaussian
    rng, felt, ball = lit_ball(11)
    c, sigma = C_TRUE, 0.8
    clean = felt + gaussian(ball, sigma, constant=True)
    samples, f, img = still_samples(rng, clean, felt)
    look, _ = learn_sphere(samples, R_PX)
    assert abs(look.psf - sigma) < 0.05
    e, z = [], []
    for _ in range(40):
        img = clean + rng.normal(0, 3.0, clean.shape)
        g = fit_disc(img, felt, U0, V0, c + [0.3, -0.2], R_PX, 170.0, shade=look)
        assert g
        e.append(g.c - c)
        z.append((g.c - c) / g.stderr)
    assert np.sqrt(np.mean(np.square(e))) < 2 * 0.0089
    assert 0.65 <= np.sqrt(np.mean(np.square(z))) <= 1.4



def test_small_blurred_matte_ball_lit_from_the_learnt_side():
    # benchmarks/track.py realistic seed 7 shot 4 in small: a matte ball
    # (no highlight) of radius 7.6 px through a lens of PSF 0.75 px, lit
    # from azimuth 3.67 (in the image) at 1.19 rad, the tracker's combined
    # levels there (felt 117, ambient 141, diffuse 217, noise 2.5).  From
    # starts without blur the best lay on the far side (a broad Blinn lobe
    # for the blurred rim) and the search stayed there: azimuth 0.50-0.53,
    # every centre 0.154-0.166 px towards the light, err/se 6.2-6.8 (seeds
    # 0-7, measured); with the starts at the lenses' middle (sphere.
    # START_PSF_VARS) azimuth 3.666-3.678, PSF 0.745-0.753, mean error
    # 0.002-0.007 px over 20 frames, err/se 0.95-1.33.  Asserted: the
    # azimuth within 0.05 rad, the PSF within 0.05 px, the mean error under
    # 0.02 px and err/se within the lens test's band.
    from cuespin.render.draw import gaussian
    rng = np.random.default_rng(0)
    shape, r, c, az = (23, 23), 7.6, np.array([U0 + 11.31, V0 + 10.72]), 3.67
    felt = 117.0 + rng.normal(0, 2, shape)
    geo = np.r_[217.0, 0.0, 0.0, SphereLook(az, 1.19, 40.0).geometry()]
    ball = streak_model(c, np.zeros(2), 141.0, felt, r, U0, V0, np.zeros(1), geo)[0]
    clean = felt + gaussian(ball, 0.75, constant=True)
    samples = []
    for _ in range(12):
        img = clean + rng.normal(0, 2.5, shape)
        f = fit_disc(img, felt, U0, V0, c + [0.3, -0.2], r, 171.0, shade=True)
        assert f
        samples.append(Sample(img, felt, U0, V0, f.c, f.b, f.G, False, f.shade, None))
    look, _ = learn_sphere(samples, r)
    assert abs(np.angle(np.exp(1j * (look.azimuth - az)))) < 0.05
    assert abs(look.psf - 0.75) < 0.05
    e, z = [], []
    for _ in range(20):
        img = clean + rng.normal(0, 2.5, shape)
        g = fit_disc(img, felt, U0, V0, c + [0.3, -0.2], r, 171.0, shade=look)
        assert g
        e.append(g.c - c)
        z.append((g.c - c) / g.stderr)
    assert np.hypot(*np.mean(e, axis=0)) < 0.02
    assert 0.65 <= np.sqrt(np.mean(np.square(z))) <= 1.4

@pytest.mark.slow
def test_rendered_highlighted_ball_centre_within_its_stated_errors(tmp_path):
    # benchmarks/track.py realistic's shot 2 (seed 0): a yellow ball on grey
    # felt, light at azimuth 3.63, elevation 1.31, a highlight (0.318,
    # shininess 27.7), 240 fps, noise 2.3, FFV1.  Measured over its 100
    # moving frames: RMSE 0.0038 px against a bound of 0.0031 (the
    # quadratic look: 0.033), err/se 0.91 (quadratic: 1.77).  The issue's
    # band for err/se is 0.8-1.25; 100 frames of a smooth track spread it by
    # a few hundredths, so the measured value passes [0.75, 1.25] and the
    # quadratic look's fails it; the RMSE is held to 2.5 times the measured
    # (the quadratic look: 8.7 times).
    from cuespin.data_gen.sampler import sample_scenes

    scene = sample_scenes(3, 0, look="realistic", codec="FFV1")[2]
    scene.render.update({"markings": "none", "psf_sigma": 0.0, "specular": 0.318, "cue": False, "balls": [],
                         "max_duration": 0.8})
    res, truth, tuv = render_and_track(scene, tmp_path / "highlight.avi")
    n = len(truth)
    moving = res.ok[:n] & (truth.t.values > scene.truth.t0 + 0.02)
    assert moving.sum() >= 80
    e = res.uv[:n][moving] - tuv[moving]
    z = float(np.sqrt(np.mean((e / res.stderr_px[:n][moving]) ** 2)))
    assert 0.75 <= z <= 1.25
    assert float(np.sqrt(np.mean(e**2))) <= 2.5 * 0.0038


@pytest.mark.slow
def test_sphere_second_minimum_under_lens_blur_is_not_kept(tmp_path):
    # benchmarks/track.py realistic's shot 4 (seed 0): an orange ball on red
    # felt under lens blur (PSF sigma 0.77 px), light at elevation 0.90,
    # 480 fps, noise 6.6, FFV1.  The centroid the fit starts from lies
    # towards the light, and the lit sphere has a second minimum there, its
    # diffuse coefficient -23 to -1 against the ball's ~55: 10 centres
    # 0.29-0.35 radii off (the quadratic look: none).  Fitted again from
    # the quadratic look's centre when the coefficient says so
    # (tracker.SPHERE_A_MIN), none; 382 of 385 frames found either way.
    from cuespin.data_gen.sampler import sample_scenes

    scene = sample_scenes(5, 0, look="realistic", codec="FFV1")[4]
    scene.render.update({"markings": "none", "psf_sigma": 0.769, "specular": 0.0, "cue": False, "balls": [],
                         "max_duration": 0.8})
    res, truth, tuv = render_and_track(scene, tmp_path / "blur.avi")
    n = len(truth)
    assert res.ok[:n].mean() >= 0.99  # issue 10's share
    err = np.hypot(*(res.uv[:n] - tuv).T)[res.ok[:n]] / res.radius_px
    assert err.max() < 0.25, f"{int((err >= 0.25).sum())} centres a quarter radius off"


def test_sphere_look_scaled_by_the_outline():
    # Under perspective the ball's image (its outline) is larger or smaller
    # than the table-wide radius the tracker passes: the shading must be
    # scaled by the outline.  An outline 1.1x r, eight noisy frames: the
    # centre's error per axis, RMS in its stated errors, was 2.35 with the
    # look at X / r, 0.64 at the outline's radius (measured, seed 2; at
    # 1.3x r 1.28 and 0.66); asserted < 1.5.
    from cuespin.track.outline import Ellipse
    c, look, rt = np.array([522.31, 305.72]), TRUTH, 1.1 * R_PX
    rng, felt, ball = lit_ball(2, rt, (45, 45), c)
    clean = felt + ball
    ol = Ellipse(((1 / rt**2, 0.0), (0.0, 1 / rt**2)))
    z = []
    for _ in range(8):
        img = np.clip(np.rint(clean + rng.normal(0, 3.0, clean.shape)), 0, 255)
        f = fit_disc(img, felt, U0, V0, c + [0.2, -0.1], R_PX, 170.0, shade=look, outline=ol)
        assert f
        z.append((f.c - c) / f.stderr)
    assert np.sqrt(np.mean(np.square(z))) < 1.5


def _imprinted_still_ball(seed: int, white: bool):
    """A small blurred matte ball (r 7.6 px, PSF 0.5-1.0 px) at rest, lit
    from a random side (elevation 0.87-1.4, data_gen's range), as the tracker
    hands it to the light's two learnings: twelve frames fitted with the
    quadratic look against a first felt that holds half of the resting
    ball's shading 1 px aside (s19: realistic seed 8 shot 19's first felt,
    sd 4.6 levels inside the disc with a gradient across it, against 8
    levels of contrast), and the better (true) felt.  ``white``: found13's
    white ball on blue felt (felt 117, ambient 141, diffuse 217, noise
    2.5); else shot 19's case, the ball 5-10 levels above the felt (diffuse
    10-20) at noise 2-3.  (the samples, the better felt, the light's image
    azimuth); None when a quadratic fit fails."""
    from cuespin.render.draw import gaussian
    rng = np.random.default_rng([seed, 19])
    shape, r = (23, 23), 7.6
    c = np.array([U0 + 11.0, V0 + 11.0]) + rng.uniform(-0.5, 0.5, 2)
    az, el, psf = rng.uniform(0, 2 * np.pi), rng.uniform(0.87, 1.4), rng.uniform(0.5, 1.0)
    if white:
        level, noise, contrast, a = 117.0, 2.5, None, 217.0
    else:
        level, noise, contrast, a = 150.0, rng.uniform(2, 3), rng.uniform(5, 10), rng.uniform(10, 20)
    felt = level + rng.normal(0, 2, shape)
    geo = np.r_[a, 0.0, 0.0, SphereLook(az, el, 40.0).geometry()]
    G = 141.0
    if contrast is not None:  # the ambient that puts the disc's mean ``contrast`` above the felt
        d0 = streak_model(c, np.zeros(2), level, felt, r, U0, V0, np.zeros(1), geo)[0]
        G = level + contrast - float(np.mean(d0[np.abs(d0) > 1e-9]))
    ball = streak_model(c, np.zeros(2), G, felt, r, U0, V0, np.zeros(1), geo)[0]
    clean = felt + gaussian(ball, psf, constant=True)
    aside = rng.uniform(0, 2 * np.pi)
    ghost = streak_model(c + [np.cos(aside), np.sin(aside)], np.zeros(2), G, felt, r, U0, V0, np.zeros(1), geo)[0]
    disc = np.abs(ghost) > 1e-9
    first = felt + 0.5 * gaussian(np.where(disc, ghost - ghost[disc].mean(), 0.0), psf, constant=True)
    samples = []
    for _ in range(12):
        img = clean + rng.normal(0, noise, shape)
        f = fit_disc(img, first, U0, V0, c + [0.3, -0.2], r, G + 30.0, shade=True)
        if not f:
            return None
        samples.append(Sample(img, first, U0, V0, f.c, f.b, f.G, False, f.shade, None))
    return samples, felt, az


@pytest.mark.slow
@pytest.mark.parametrize("white, most_after, before", [(True, 0, 15), (False, 2, 12)])
def test_relearn_searches_both_sides_of_the_light(white, most_after, before):
    # sphere.relearn_both_sides (s19, realistic seed 8 shot 19): the light
    # learnt first against a felt that holds the resting ball's shading may
    # land on the wrong side (azimuth ~pi off); learnt again against the
    # better felt from that look only, it stayed there.  Twenty seeds of
    # _imprinted_still_ball each, the learnt azimuth more than pi/2 from the
    # render's counted (a relearn that fails keeps the first look, as
    # BallTracker.relearn_sphere does), measured: white on blue, first look
    # 15 of 20 wrong, relearnt from it 15, from both sides 0; shot 19's low
    # contrast, 12 of 20, 12 and 2 (seed 8: right from its start, the
    # mirror converges lower; seed 15: wrong both ways; the objectives are
    # on three single noisy frames there, the quadratic centres scattering
    # more than sphere.STILL_PX).
    # Asserted: both sides at most the measured count; one side near its
    # measured count (review 14, SHOULD 5: the compass search's path turns
    # on rounding -- seed 8's mirror ends at 6850 or 4360 by how its start
    # angle is written -- so another BLAS or CPU may move a seed or two of
    # the one-sided search, the context rather than the claim).
    wrong = {"one side": 0, "both sides": 0}
    n = 0
    for seed in range(20):
        got = _imprinted_still_ball(seed, white)
        if got is None:
            continue
        samples, felt, az = got
        n += 1
        first, _ = learn_sphere(samples, 7.6)
        better = [s._replace(felt=felt) for s in samples]
        for name, (look, _) in (("one side", learn_sphere(better, 7.6, start=first)),
                                ("both sides", relearn_both_sides(better, 7.6, first))):
            look = first if look is None else look
            wrong[name] += abs(np.angle(np.exp(1j * (look.azimuth - az)))) > np.pi / 2
    assert n == 20
    assert wrong["one side"] >= before - 2
    assert wrong["both sides"] <= most_after
