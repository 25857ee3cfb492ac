"""Contacts: the shot continued past cushions and balls, and the first contact found in a track."""

import sys
from pathlib import Path

import numpy as np
import pytest

from cuespin.data_gen.sampler import sample_scene, sample_shot
from cuespin.fit.contact import (
    CHANGE_THRESHOLD, MEASURED_NULL_MAX, Contact, analysed_frames, find_contact,
)
from cuespin.physics.contact import (
    BALL_RESTITUTION, CUSHION_RESTITUTION, scene_balls, scene_trajectory, simulate,
)
from cuespin.physics.motion import BallParams, Shot, kinetic_energy, positions
from cuespin.physics.scene import Table

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from contact import calibrate, detect  # noqa: E402  (benchmarks/contact.py)

P = BallParams()
TABLE = Table()


def contact_scenes(n, seed=0):
    return [sample_scene(seed + i, ("cushion", "ball_contact")[i % 2]) for i in range(n)]


def test_energy_never_rises_across_a_contact():
    checked = 0
    for scene in contact_scenes(40):
        traj = scene_trajectory(scene)
        R = scene.physics.R
        for c in traj.contacts:
            before, after = traj.state([c.t - 1e-9, c.t + 1e-9]), None
            after = traj.state([c.t + 1e-9])
            e0 = kinetic_energy(before.v[0], before.w[0], R)
            e1 = kinetic_energy(after.v[0], after.w[0], R)
            if c.kind == "ball":  # the struck ball's share counts too
                struck = dict(traj.struck)[c.other].state([c.t + 1e-9])
                e1 = e1 + kinetic_energy(struck.v[0], struck.w[0], R)
            assert e1 <= e0 * (1 + 1e-6) + 1e-12
            checked += 1
        # and friction never adds any between contacts
        t = np.linspace(scene.truth.t0 + 1e-6, min(traj.t_rest, scene.truth.t0 + 8), 4000)
        st = traj.state(t)
        assert np.diff(kinetic_energy(st.v, st.w, R)).max() <= 1e-9
    assert checked >= 60


def test_cushion_reflects_normal_velocity_with_restitution():
    # Rolling straight at the x = length cushion, with some sideways speed.
    shot = Shot(x0=(1.5, 0.5), v0=(2.0, 0.3), w0=(-0.3 / P.R, 2.0 / P.R), t0=0.1)
    traj = simulate(shot, P, TABLE, restitution=0.8)
    c = traj.first_contact
    assert c.kind == "cushion" and c.normal == (-1.0, 0.0)
    assert c.point[0] == pytest.approx(TABLE.length - P.R, abs=1e-9)
    before, after = traj.state([c.t - 1e-10]), traj.state([c.t + 1e-10])
    assert after.v[0, 0] == pytest.approx(-0.8 * before.v[0, 0], rel=1e-6)
    assert after.v[0, 1] == pytest.approx(before.v[0, 1], rel=1e-6)
    np.testing.assert_allclose(after.w[0], before.w[0], rtol=1e-6)  # spin kept
    # Before the contact it is the paper's model exactly.
    t = np.linspace(0, c.t, 500)
    np.testing.assert_array_equal(traj.positions(t), positions(shot, P, t))


def test_ball_contact_passes_the_normal_velocity():
    shot = Shot(x0=(0.5, 0.6), v0=(1.5, 0.0), w0=(0.0, 1.5 / P.R), t0=0.0)
    ball = np.array([[1.2, 0.6 + 0.8 * P.R]])
    traj = simulate(shot, P, TABLE, balls=ball)
    c = traj.first_contact
    assert c.kind == "ball" and c.other == 0
    assert np.hypot(*(np.array(c.point) - ball[0])) == pytest.approx(2 * P.R, rel=1e-9)
    n = np.array(c.normal)
    v0 = traj.state([c.t - 1e-10]).v[0]
    v1 = traj.state([c.t + 1e-10]).v[0]
    vb = dict(traj.struck)[0].state([c.t + 1e-10]).v[0]
    np.testing.assert_allclose(v0, v1 + vb, atol=1e-8)  # equal masses: momentum kept
    assert vb @ n == pytest.approx((1 + BALL_RESTITUTION) / 2 * (v0 @ n), rel=1e-6)
    t_perp = np.array([-n[1], n[0]])
    assert v1 @ t_perp == pytest.approx(v0 @ t_perp, rel=1e-6)


def test_ball_stays_on_the_table_and_off_other_balls():
    for scene in contact_scenes(20, seed=100):
        traj = scene_trajectory(scene)
        R = scene.physics.R
        t = np.linspace(0, min(traj.t_rest, 15.0), 20000)
        x = traj.positions(t)
        assert scene.table.contains(x, margin=R - 1e-9).all()
        balls = scene_balls(scene.render)
        for j, b in enumerate(balls):
            hit = [c.t for c in traj.contacts if c.other == j]
            before = t < (hit[0] if hit else np.inf)
            assert (np.hypot(*(x[before] - b).T) >= 2 * R - 1e-9).all()
        # vectorised in any order
        perm = np.random.default_rng(0).permutation(len(t))
        np.testing.assert_array_equal(traj.positions(t[perm]), x[perm])
        assert traj.angular_velocity(t[:5]).shape == (5, 2)


def test_contacts_off_is_the_paper_model():
    shot, params = sample_shot(3, "leaves_table")
    scene = sample_scene(3, "leaves_table")
    traj = scene_trajectory(scene)
    assert traj.contacts == () and len(traj.segments) == 1
    t = np.linspace(0, 3, 100)
    np.testing.assert_array_equal(traj.positions(t), positions(scene.truth, scene.physics, t))
    assert CUSHION_RESTITUTION == 0.9


def test_no_contact_found_on_contact_free_tracks():
    # The threshold's calibration: contact-free simulated tracks (every
    # preset, 60-480 fps, noise 0.005-0.5 px) stay below it (600 such: max
    # MEASURED_NULL_MAX, under 2/3 of the threshold).
    m = calibrate(24, seed=11)
    assert m.max() < CHANGE_THRESHOLD
    assert MEASURED_NULL_MAX < CHANGE_THRESHOLD * 2 / 3


def test_contact_found_within_one_frame_on_simulated_tracks():
    # benchmarks/contact.py detect --n 200 --seed 3: 199 of 200 within one
    # frame or found early; one ball contact (0.15 m/s change at 0.35 px
    # noise) was within the noise and not found.
    rows = detect(24, seed=5)
    found = np.array([r[4] for r in rows])
    err = found - np.array([r[3] for r in rows])
    assert (found >= 0).sum() >= 23
    assert (np.abs(err[found >= 0]) <= 1).all()
    assert [r[6] for r in rows if r[4] >= 0] == [r[5] for r in rows if r[4] >= 0]  # cushion / ball
    t_err = np.array([r[8] - r[7] for r in rows if r[4] >= 0])
    fps = np.array([r[1] for r in rows if r[4] >= 0])
    assert np.abs(t_err * fps).max() <= 1.0


def test_analysed_frames_stop_before_the_contact():
    t = np.arange(100) / 100.0
    c = Contact(t=0.505, index=51, kind="cushion")
    assert analysed_frames(t, None) == 100
    assert analysed_frames(t, c, margin=0) == 51         # frames 0..50, t <= 0.50
    assert analysed_frames(t, c) == 50                   # one frame of margin
    assert analysed_frames(t, c, exposure_s=0.02, margin=0) == 50  # frame 50's exposure reaches 0.51


def test_ball_coming_back_is_not_the_shot():
    # A fast shot into a cushion: the track after the bounce would fit a
    # different shot; the analysed frames end before the contact.
    shot = Shot(x0=(1.9, 0.6), v0=(2.5, 0.2), w0=(0.0, 2.5 / P.R), t0=0.2)
    traj = simulate(shot, P, TABLE)
    fps = 120.0
    t = np.arange(int(2.5 * fps)) / fps
    rng = np.random.default_rng(3)
    xy = traj.positions(t) + 2e-5 * rng.standard_normal((len(t), 2))
    c = find_contact(t, xy, np.ones(len(t), bool), 2e-5, TABLE, P.R)
    assert c is not None and c.kind == "cushion"
    n = analysed_frames(t, c)
    assert t[n - 1] < traj.first_contact.t
    assert abs(c.index - np.searchsorted(t, traj.first_contact.t)) <= 1


def test_gentle_ball_contact_found_where_the_path_meets_the_ball():
    # A near-glancing contact (0.35 m/s turned by 0.15 m/s) under 0.3 mm of
    # tracking noise: the change test alone misses it (None on these five
    # seeds), the path meeting a ball the scene lists finds it within one
    # frame.  On the realistic look's render of ball_contact seed 4 (120
    # fps) the change statistic was 36 against the threshold's 40.
    ball = np.array([[1.2, 0.5 + 2 * P.R * 0.9]])
    shot = Shot(x0=(0.6, 0.5), v0=(0.45, 0.0), w0=(0.0, 0.45 / P.R), t0=0.2)
    traj = simulate(shot, P, TABLE, balls=ball)
    t = np.arange(360) / 120.0
    true_index = np.searchsorted(t, traj.first_contact.t)
    for seed in range(5):
        xy = traj.positions(t) + 3e-4 * np.random.default_rng(seed).standard_normal((len(t), 2))
        c = find_contact(t, xy, np.ones(len(t), bool), 3e-4, TABLE, P.R, ball)
        assert c is not None and c.kind == "ball"
        assert abs(c.index - true_index) <= 1 and abs(c.t - traj.first_contact.t) * 120.0 <= 1.0


def rendered_contact(tmp_path, preset, seed, fps, px_per_m, codec="FFV1", look="plain"):
    """Render a contact scene to 0.3 s after its first contact and recover it."""
    import dataclasses

    from cuespin.pipeline.run import run_recover
    from cuespin.render.video import render_video

    scene = sample_scene(seed, preset, fps=fps, px_per_m=px_per_m, noise=2.0, blur=False, codec=codec, look=look)
    first = scene_trajectory(scene).first_contact
    scene = dataclasses.replace(scene, render={**scene.render, "duration": first.t + 0.3})
    video = tmp_path / f"{preset}.avi"
    truth = render_video(scene, video)
    res = run_recover(video, scene, method="mle")
    return scene, first, truth, res


def check_rendered(scene, first, truth, res):
    c = res["track"]["contact"]
    assert c is not None and c["kind"] == first.kind
    true_index = np.searchsorted(truth.t, first.t)
    found_index = np.searchsorted(truth.t, c["t"] - 1e-12)
    assert abs(found_index - true_index) <= 1
    m = res["methods"]["mle"]
    assert m["status"] == "ok", m["reason"]
    # The frames before the contact answer as the paper's shot: within 5
    # stated standard errors (the bounce's frames, if used, would be off by
    # metres per second).
    for key in ("v0", "w0"):
        err = np.abs(np.array(m[key]) - np.array(getattr(scene.truth, key)))
        assert (err < 5 * np.array(m["stderr"][key])).all(), (key, err, m["stderr"][key])


def test_rendered_cushion_shot_end_to_end(tmp_path):
    check_rendered(*rendered_contact(tmp_path, "cushion", 1, 60.0, 200.0))


@pytest.mark.slow  # two 120 fps renders and tracks: about 50 s on a loaded machine
@pytest.mark.parametrize("preset,seed", [("cushion", 1), ("ball_contact", 4)])
def test_rendered_contact_shots_end_to_end_120fps(tmp_path, preset, seed):
    check_rendered(*rendered_contact(tmp_path, preset, seed, 120.0, 250.0))


@pytest.mark.slow  # a realistic 120 fps render and track: about 4 min on a loaded machine
def test_rendered_ball_contact_with_the_other_balls_drawn(tmp_path):
    """The realistic look draws the other balls, the struck one moving after
    the contact: the contact is found within one frame as a ball's, and the
    struck ball is not taken for the shot.  (The realistic look's stated
    errors are not yet honest, README known limits: the answer is not
    checked against them here.)"""
    scene, first, truth, res = rendered_contact(tmp_path, "ball_contact", 4, 120.0, 250.0, look="realistic")
    c = res["track"]["contact"]
    assert c is not None and c["kind"] == "ball"
    true_index = np.searchsorted(truth.t, first.t)
    assert abs(np.searchsorted(truth.t, c["t"] - 1e-12) - true_index) <= 1
    assert res["methods"]["mle"]["status"] == "ok"


# Contact-free tracks with an inter-frame codec's errors (recover.simulate,
# INTER_CODEC_ACF), half rolling from the strike, half sliding, at 60-480
# fps and 0.05-1 px at 500 px/m (realistic H.264's stated errors): the
# change test read with independent errors finds a contact on 9 of 240
# (all at 480 fps, statistics 40.4-44.9; seed 36's H.264 tracks 6, 7, 23
# and 26 were cut 252-585 frames short so; 13 of these 400), with the
# errors' correlation on none of 400 (docs/measurements.md contact36,
# chi2c).  The threshold's own calibration saw none of 600
# independent-error tracks over it (max 25.5): the nominal rate is taken as
# 1 in 200, and the test allows it plus two binomial standard errors over
# 400 null tracks (issue 11): 2 + 2 x 1.41, 4 of 400.
CORRELATED_NULL_N = 400
CORRELATED_NULL_MAX_FALSE = 4
CORRELATED_NULL_SIGMAS = (1e-4, 6e-4, 2e-3)


def correlated_null_contacts(time_corr, n=CORRELATED_NULL_N, seed=5):
    from cuespin.recover.mle import INTER_CODEC_ACF
    from cuespin.recover.simulate import null_rolling_tracks, sliding_tracks

    big = Table(length=100.0, width=100.0)  # the generator's shots run through cushions: none here
    found = 0
    for gen in (null_rolling_tracks(n // 2, seed, sigma_grid=CORRELATED_NULL_SIGMAS, acf=INTER_CODEC_ACF),
                sliding_tracks(n - n // 2, seed + 1, sigma_grid=CORRELATED_NULL_SIGMAS, acf=INTER_CODEC_ACF)):
        for tr in gen:
            c = find_contact(tr.t, tr.xy + 50.0, np.ones(len(tr.t), bool), tr.sigma, big, tr.params.R,
                             time_corr=time_corr)
            found += c is not None
    return found


@pytest.mark.slow  # 400 simulated tracks twice: 22 s alone, more on a loaded machine
def test_no_contact_from_a_codecs_correlated_errors():
    from cuespin.recover.mle import time_correlation

    assert correlated_null_contacts(None) >= 5   # the generator shows the independent reading's fault
    assert correlated_null_contacts(time_correlation) <= CORRELATED_NULL_MAX_FALSE


def test_one_stray_first_frame_does_not_make_the_strike_a_contact():
    # Seed 34's H.264 shot 27: its first frame 7 stated errors off made every
    # later frame "moved", and the strike was found as an "unknown" contact
    # (statistic 50), cutting a correct track.  Here 15 errors off, 5 seeds.
    shot = Shot(x0=(1.0, 0.6), v0=(0.4, 0.1), w0=(-0.1 / P.R, 0.4 / P.R), t0=0.4)
    traj = simulate(shot, P, TABLE)
    t = np.arange(360) / 240.0
    for seed in range(5):
        xy = traj.positions(t) + 1e-4 * np.random.default_rng(seed).standard_normal((len(t), 2))
        xy[0] += 1.5e-3
        assert find_contact(t, xy, np.ones(len(t), bool), 1e-4, TABLE, P.R) is None


@pytest.mark.slow
def test_a_contact_near_the_tracks_end_is_not_divided_away_by_the_shots_drift():
    # Review of contact36 (its /tmp/revlate/pow.py, seed 4): contact scenes
    # with H.264-like errors correlated in time on a 100-m table (no cushion,
    # no listed ball: the change test alone), each track cut 0.25 s after
    # its contact.  The shot's drift read from the statistic's median took
    # the changes' own windows for drift: shots 3 (240 fps) and 29 (60 fps),
    # found by the independent reading, were missed (29's peak 4767 -> 82.6
    # and under the threshold after).  Read from the lower quartile, capped
    # (shot_drift2), both are found within 2 frames as the independent
    # reading finds them.
    from contact import CONTACT_PRESETS, noise_level, simulated_track

    from cuespin.recover.mle import time_correlation
    from cuespin.recover.simulate import shared_errors

    big = Table(length=100.0, width=100.0)
    rng = np.random.default_rng(4)
    for i in range(30):
        scene = sample_scene(int(rng.integers(2**31)), CONTACT_PRESETS[i % 2])
        t, xy, se, traj = simulated_track(scene, noise_level(rng) * 10, rng)
        xy = traj.positions(t) + se[0] * shared_errors(len(t), scene.camera.fps, rng)
        if i not in (3, 29):
            continue
        tc = traj.first_contact.t
        ti = int(np.searchsorted(t, tc))
        m = t <= tc + 0.25
        for corr in (None, time_correlation):
            c = find_contact(t[m], xy[m], np.ones(m.sum(), bool), se[m], big, scene.physics.R, (), time_corr=corr)
            assert c is not None and abs(c.index - ti) <= 2, (i, corr, c)


def test_a_wandering_rest_does_not_make_the_strike_a_contact(monkeypatch):
    # Realistic H.264 38/21 (held37): the resting ball's track wandered 0.5
    # px, "moved" fired at 0.10 s, and the strike at 0.40 s was cut as an
    # "unknown" contact, leaving 0 frames of motion.  Here the rest drifts
    # 15 stated errors before the strike: without fit.contact.strike_at
    # every track below is cut at its strike (statistic 50-1340).  A change
    # whose window before shows the ball still is the strike, not a contact.
    import cuespin.fit.contact as contact_module

    shot = Shot(x0=(1.0, 0.6), v0=(0.4, 0.1), w0=(-0.1 / P.R, 0.4 / P.R), t0=0.4)
    traj = simulate(shot, P, TABLE)
    cut_before = 0
    for fps in (60.0, 120.0, 240.0):
        t = np.arange(int(0.9 * fps)) / fps
        for seed in range(3):
            xy = traj.positions(t) + 1e-4 * np.random.default_rng(seed).standard_normal((len(t), 2))
            rest = t < shot.t0
            xy[rest] += np.outer(t[rest] / shot.t0, [1.5e-3, 0.0])
            assert find_contact(t, xy, np.ones(len(t), bool), 1e-4, TABLE, P.R) is None, (fps, seed)
            with monkeypatch.context() as mp:
                mp.setattr(contact_module, "strike_at", lambda *a: False)
                old = find_contact(t, xy, np.ones(len(t), bool), 1e-4, TABLE, P.R)
            cut_before += old is not None and abs(old.t - shot.t0) < 1.0 / fps
    assert cut_before == 9  # the case this is about


def restrike_track(rng, k: int):
    """A ball rolls to rest and is struck again 0.3 s after it stops (the
    review of pap37's rehit.py): frame times (s), centres (m), the error (m)
    and the second strike's time (s)."""
    fps = (60.0, 120.0, 240.0, 480.0)[k % 4]
    sig = (1e-4, 6e-4)[(k // 4) % 2]
    sp = rng.uniform(0.15, 0.4)
    ang = rng.uniform(0, 2 * np.pi)
    d = np.array([np.cos(ang), np.sin(ang)])
    first = simulate(Shot(x0=(1.27, 0.635), v0=tuple(sp * d), w0=tuple(np.array([-d[1], d[0]]) * sp / P.R),
                          t0=0.2), P, TABLE)
    th = first.t_rest + 0.3
    x2 = first.positions(np.array([first.t_rest + 0.01]))[0]
    ang2 = rng.uniform(0, 2 * np.pi)
    d2 = np.array([np.cos(ang2), np.sin(ang2)])
    sp2 = rng.uniform(0.3, 1.0)
    second = simulate(Shot(x0=tuple(x2), v0=tuple(sp2 * d2), w0=tuple(np.array([-d2[1], d2[0]]) * sp2 / P.R),
                           t0=th), P, TABLE)
    t = np.arange(int((th + 0.5) * fps)) / fps
    xy = np.where((t < th)[:, None], first.positions(t), second.positions(t)) + sig * rng.standard_normal((len(t), 2))
    return t, xy, sig, th


def test_a_restrike_after_a_rest_is_a_contact():
    # Review of pap37 (rehit.py): with strike_at asking only the window
    # before a change, at 50 ("slow", not "still"), a second strike 0.3 s
    # after the ball came to rest was taken for the strike and passed over:
    # found in 0 of these 8 (8 of 8 without strike_at).  The track's first
    # motion is the strike; every later change is a contact.
    rng = np.random.default_rng(1)
    for k in range(8):
        t, xy, sig, th = restrike_track(rng, k)
        c = find_contact(t, xy, np.ones(len(t), bool), sig, TABLE, P.R)
        assert c is not None and abs(c.t - th) < 0.05, (k, c)


def paired_contact_scenes(rules, n=400, seed=41):
    """Contacts found on ``n`` contact scenes on a 100-m table (no cushion,
    no listed ball: the change test alone), each cut 0.25 s after its
    contact, with independent and H.264-like correlated errors, under each
    rule: ``rules`` maps a name to the ``(module, attribute, value)`` set
    for it.  Returns ``{(errors, name): [found, ...]}``."""
    from contact import CONTACT_PRESETS, noise_level, simulated_track

    from cuespin.recover.mle import time_correlation
    from cuespin.recover.simulate import shared_errors

    big = Table(length=100.0, width=100.0)
    rng = np.random.default_rng(seed)
    found = {}
    for i in range(n):
        scene = sample_scene(int(rng.integers(2**31)), CONTACT_PRESETS[i % 2])
        t, xy, se, traj = simulated_track(scene, noise_level(rng) * 10, rng)
        xys = {"indep": xy, "corr": traj.positions(t) + se[0] * shared_errors(len(t), scene.camera.fps, rng)}
        m = t <= traj.first_contact.t + 0.25
        for errs, X in xys.items():
            for name, sets in rules.items():
                with pytest.MonkeyPatch.context() as mp:
                    for module, attr, value in sets:
                        mp.setattr(module, attr, value)
                    c = find_contact(t[m], X[m], np.ones(m.sum(), bool), se[m], big, scene.physics.R, (),
                                     time_corr=None if errs == "indep" else time_correlation)
                found.setdefault((errs, name), []).append(c is not None)
    return found


@pytest.mark.slow  # 400 contact scenes, 2 error kinds, 2 rules: about 1-3 min
def test_strike_at_loses_no_contacts():
    # Review of pap37 (strike_power.py 400 41 0.25): contact scenes on a
    # 100-m table (no cushion, no listed ball: the change test alone), each
    # cut 0.25 s after its contact, independent and H.264-like correlated
    # errors.  pap37's strike_at missed 84 (independent) and 104 (correlated)
    # of the 400 against 75 and 95 with it off: 9 losses each, no gain.
    # Asked: the contacts lost against those gained, paired on the same
    # scenes, within McNemar's two-standard-error margin (losses - gains <=
    # 2 sqrt(losses + gains)).
    import cuespin.fit.contact as contact_module

    found = paired_contact_scenes({"landed": [], "off": [(contact_module, "strike_at", lambda *a, **k: False)]})
    for errs in ("indep", "corr"):
        a, b = np.array(found[(errs, "landed")]), np.array(found[(errs, "off")])
        lost, gained = int(np.sum(b & ~a)), int(np.sum(a & ~b))
        assert lost - gained <= 2 * np.sqrt(lost + gained), (errs, lost, gained)


@pytest.mark.slow
def test_a_still_rest_is_still_at_the_strike_tests_level():
    # strike_at's still test (fit.contact.STILL_LEVEL, Bonferroni over the
    # windows: family-wise at most 0.1%) on 800 rests that never move, 0.5 s
    # at 60-480 fps, independent errors and an inter-frame codec's correlated
    # ones (read with its correlation, as find_contact reads H.264): a rest
    # read "moved" would leave its strike to be cut as an unknown contact
    # (realistic H.264 38/21, pap37).  Allowed: 800 x 0.1% plus two binomial
    # standard errors, 3; measured 0 of 800 (review of fixpap, SHOULD 3).
    from cuespin.fit import contact as C
    from cuespin.recover.mle import time_correlation
    from cuespin.recover.simulate import shared_errors
    rng = np.random.default_rng(11)
    moved = 0
    for kind in ("independent", "codec"):
        for fps in (60.0, 120.0, 240.0, 480.0):
            for _ in range(100):
                n, sig = int(fps * 0.5), 1e-4
                t = np.arange(n) / fps
                e = rng.standard_normal((n, 2)) if kind == "independent" else shared_errors(n, fps, rng)
                xy = np.array([1.0, 0.5]) + sig * e
                b, _, scale, (cl, _) = C.change_statistic(t, xy, np.full(n, sig),
                                                          time_corr=time_correlation if kind == "codec" else None)
                W = C.window_frames(t)
                covl = C._window_fits(t, xy, np.full(n, sig), b - W, W, 0.5 * (t[b - 1] + t[b]))[1]
                moved += not C.strike_at(cl, covl, scale)
    assert moved <= 3, moved


def test_a_run_of_frames_off_the_path_is_not_a_contact(monkeypatch):
    # Realistic H.264 48/13 (docs/measurements.md, held39 and rimdot): frames
    # 57, 59, 63 and 64 of a 60-fps slide 4-5 stated errors off where a dark
    # dot reaches the ball's rim, the path the same on either side; the change
    # test cut an "unknown" contact there and the fit ended the slide between
    # them, `ok` at 15 stated errors.  Here the same pattern (frames k, k+2,
    # k+6, k+7 six errors off along x, 4.2 along y) on the forward model, 10
    # seeds: without the rule (MAX_OUTLIER_SHARE 0) most are cut, with it none.
    import cuespin.fit.contact as contact_module

    shot = Shot(x0=(0.5, 0.4), v0=(0.9, 0.35), w0=(-12.0, 40.0), t0=0.15)
    traj = simulate(shot, P, TABLE)
    t = np.arange(70) / 60.0
    sig = 5e-4
    found = {}
    for share in (0.0, contact_module.MAX_OUTLIER_SHARE):
        monkeypatch.setattr(contact_module, "MAX_OUTLIER_SHARE", share)
        for seed in range(10):
            xy = traj.positions(t) + sig * np.random.default_rng(seed).standard_normal((len(t), 2))
            xy[[47, 49, 53, 54]] += 6.0 * sig * np.array([1.0, 0.7])
            c = find_contact(t, xy, np.ones(len(t), bool), sig, TABLE, P.R)
            found.setdefault(share, []).append(c)
    assert sum(c is not None and c.kind == "unknown" for c in found[0.0]) >= 5
    assert all(c is None for c in found[contact_module.MAX_OUTLIER_SHARE])


def test_frames_off_the_path_are_found_at_their_level_on_clean_tracks():
    # fit.contact.outlier_frames on 400 windows of 2 W frames within one
    # phase (sliding or rolling: one quadratic) of contact-free simulated
    # tracks (benchmarks/contact.py's, noise 0.005-0.5 px): a window with a
    # frame taken off at most OUTLIER_LEVEL of the time plus two binomial
    # standard errors (measured: 4 of 400, seed 7).
    from contact import NULL_PRESETS, noise_level, simulated_track

    from cuespin.fit.contact import OUTLIER_LEVEL, outlier_frames, window_frames
    from cuespin.physics.motion import phases

    rng = np.random.default_rng(7)
    flagged = used = i = 0
    while used < 400:
        scene = sample_scene(int(rng.integers(2**31)), NULL_PRESETS[i % len(NULL_PRESETS)])
        i += 1
        t, xy, se, _ = simulated_track(scene, noise_level(rng), rng)
        W = window_frames(t)
        ph = phases(scene.truth, scene.physics)
        for lo, hi in ((scene.truth.t0, ph.t1), (ph.t1, ph.t2)):
            k = np.flatnonzero((t > lo) & (t < hi))
            if len(k) >= 2 * W:
                s = int(rng.integers(k[0], k[-1] - 2 * W + 2))
                flagged += outlier_frames(t, xy, se, np.arange(s, s + 2 * W)).size > 0
                used += 1
                break
    assert flagged <= 400 * OUTLIER_LEVEL + 2 * np.sqrt(400 * OUTLIER_LEVEL * (1 - OUTLIER_LEVEL))


@pytest.mark.slow  # 400 contact scenes, 2 error kinds, the rule on and off: about 2-3 min
def test_the_outlier_rule_loses_no_contacts():
    # As test_strike_at_loses_no_contacts: contact scenes on a 100-m table
    # (the change test alone), cut 0.25 s after the contact, independent and
    # H.264-like errors, the rule on and off (MAX_OUTLIER_SHARE 0).  Measured
    # (seed 41): independent 325 found either way; correlated 304 / 305 (one
    # lost, none gained).  At the change threshold in place of
    # SAME_MOTION_CHI2 it lost 13 and 17.  Asked: losses - gains within
    # McNemar's two-standard-error margin.
    import cuespin.fit.contact as contact_module

    found = paired_contact_scenes({"on": [], "off": [(contact_module, "MAX_OUTLIER_SHARE", 0.0)]})
    for errs in ("indep", "corr"):
        a, b = np.array(found[(errs, "on")]), np.array(found[(errs, "off")])
        lost, gained = int(np.sum(b & ~a)), int(np.sum(a & ~b))
        assert lost - gained <= 2 * np.sqrt(lost + gained), (errs, lost, gained)


def _injected_runs(seed, q_cycle=(1 / 16, 1 / 8, 3 / 16, 1 / 4, 5 / 16, 3 / 8), off=(4.0, 6.0)):
    """Contact-free generated tracks (benchmarks/contact.py's NULL_PRESETS,
    noise 0.005-0.5 px), each with a run off the path injected: round(q 2W)
    frames (q cycling over ``q_cycle``) among W consecutive moving frames,
    each ``off`` stated errors off one way (48/13: 4 frames among 8, 4-5
    errors).  Yields ``(t, xy, se, R)`` (/tmp/gapcov/shareB.py's tracks)."""
    from contact import NULL_PRESETS, noise_level, simulated_track

    from cuespin.fit.contact import window_frames

    rng = np.random.default_rng(seed)
    i = used = 0
    while True:
        scene = sample_scene(int(rng.integers(2**31)), NULL_PRESETS[i % len(NULL_PRESETS)])
        i += 1
        t, xy, se, _ = simulated_track(scene, noise_level(rng), rng)
        W = window_frames(t)
        mv = np.flatnonzero(t > scene.truth.t0 + 2 * W / scene.camera.fps)
        if len(mv) < 4 * W + 2:
            continue
        m = max(1, int(round(q_cycle[used % len(q_cycle)] * 2 * W)))
        used += 1
        s0 = int(rng.integers(mv[0] + W, mv[-1] - 2 * W))
        frames = s0 + np.sort(rng.choice(W, size=min(m, W), replace=False))
        ang = rng.uniform(0, 2 * np.pi)
        xy = xy.copy()
        xy[frames] += rng.uniform(*off) * se[frames, None] * np.array([np.cos(ang), np.sin(ang)])
        yield t, xy, se, scene.physics.R


def test_the_outlier_share_is_the_largest_a_cleared_run_needed(monkeypatch):
    # fit.contact.MAX_OUTLIER_SHARE (docs/measurements.md, gapcov): of 300
    # generated runs the rule cleared 12, needing 1/8 (9), 3/16 (2) and 1/4
    # (1: seed 5's fourth, 6 frames of a 12-frame window's 24, 120 fps);
    # none more.  That run is cleared at 1/4 and not at 3/16.  And the share
    # leaves each side of a boundary the 3 frames its quadratic needs when
    # every frame taken off falls on it, at every window size.
    import cuespin.fit.contact as contact_module
    from cuespin.fit.contact import MAX_OUTLIER_SHARE, MAX_WINDOW, MIN_WINDOW

    big = Table(length=100.0, width=100.0)
    runs = _injected_runs(5)
    for _ in range(3):
        next(runs)
    t, xy, se, R = next(runs)
    found = {}
    for share in (0.0, 3 / 16, MAX_OUTLIER_SHARE):
        monkeypatch.setattr(contact_module, "MAX_OUTLIER_SHARE", share)
        found[share] = find_contact(t, xy, np.ones(len(t), bool), se, big, R, ())
    assert found[0.0] is not None and found[3 / 16] is not None  # the run reads as a contact
    assert found[MAX_OUTLIER_SHARE] is None
    assert all(int(MAX_OUTLIER_SHARE * 2 * W) <= W - 3 for W in range(MIN_WINDOW, MAX_WINDOW + 1))
