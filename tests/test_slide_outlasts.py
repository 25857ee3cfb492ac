"""A rolling answer from a ball seen too briefly to show a slide
(recover.mle.SLIDE_THROUGH_TAU): a fast shot leaving the table 0.1-0.3 s
after the strike may slide through every frame seen, and "rolling from
the strike" then stated w0 10-53 errors off on realistic H.264 renders
(docs/measurements.md gross13).  Such answers are degenerate (w0 not
determined); true rolling shots seen long enough stay ok.  And a track
whose strike is not in view (no frame the fit uses shows the ball still
before t0: fit.decide.strike_in_view) is degenerate, not extrapolated."""

import numpy as np
import pytest

import cuespin.recover.mle as mle_module
from cuespin.fit.decide import Decision, slide_through_excluded
from cuespin.physics.motion import BallParams
from cuespin.recover.estimate import estimate
from cuespin.recover.simulate import leaves_table_tracks, null_rolling_tracks

# A miss this many stated errors off is a confident wrong number, not chance.
GROSS_Z = 10.0


def _recover(tr):
    return estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s, run_paper=False).mle


def _rolling_z(tr, m):
    """The rolling ok answer's largest |error| in stated errors, else None."""
    if m.status != "ok" or m.model != "rolling":
        return None
    err = np.r_[m.v0 - tr.shot.v0, m.w0 - tr.shot.w0]
    return float(np.max(np.abs(err) / np.r_[m.stderr["v0"], m.stderr["w0"]]))


# The noisiest generator level: where the rule acted on benchmarks/leaves_table.py
# (seed 31: 3 of 80 answered rolling, all > 10 errors off, before; none after).
TRACKS = dict(n=48, seed=0, sigma_grid=(6e-4,))


def test_slide_through_the_track_is_not_answered_rolling(monkeypatch):
    tracks = list(leaves_table_tracks(**TRACKS))
    # Without the rule these tracks give confident wrong rolling answers (the
    # case this is about; the assertion below fails on the code before it).
    with monkeypatch.context() as mp:
        mp.setattr(mle_module, "SLIDE_THROUGH_TAU", 0.0)
        mp.setattr(mle_module, "slide_through_excluded", lambda d: Decision(True, d, 0.0))  # gross16's too
        before = [_rolling_z(tr, _recover(tr)) for tr in tracks]
    assert sum(z is not None and z > GROSS_Z for z in before) >= 2, before
    refused = 0
    for tr in tracks:
        m = _recover(tr)
        z = _rolling_z(tr, m)
        assert z is None or z <= GROSS_Z, (tr.fps, z, m.reason)
        if m.verdicts.get("slide_outlasts"):
            refused += 1
            assert m.status == "degenerate" and m.w0 is None and "not told from sliding" in m.reason
            assert m.v0 is not None  # v0 is still given
    assert refused >= 2


def test_rolling_shots_seen_long_enough_stay_ok():
    # Rolling from the strike, leaving the table at 1e-4 m noise: none refused
    # (benchmarks/leaves_table.py --rolling, seed 31: 0 of 160 at 2e-5 and 1e-4 m;
    # 17 of 80 at 6e-4 m, seen too briefly to tell rolling from sliding).
    for tr in leaves_table_tracks(16, 1, sigma_grid=(1e-4,), preset="case4"):
        m = _recover(tr)
        assert not m.verdicts.get("slide_outlasts"), (tr.fps, m.reason)


@pytest.mark.slow
def test_full_length_rolling_tracks_never_refused():
    # 400 generator tracks rolling from the strike (seed 31): none refused
    # by either rule (measured: 398 ok, 2 degenerate for v0; gross16's
    # chi-square of a slide through every frame over 9.2 on all 397 rolling
    # answers).  The nominal rate, fit.decide.LEVEL, plus two binomial
    # standard errors would allow 7.
    from cuespin.fit.decide import LEVEL
    n = 400
    refused = sum(bool(_recover(tr).verdicts.get("slide_outlasts")) for tr in null_rolling_tracks(n, 31))
    assert refused <= n * LEVEL + 2 * np.sqrt(n * LEVEL * (1 - LEVEL))
    assert refused == 0


@pytest.mark.slow
def test_short_rolling_tracks_refused_only_by_the_seen_time_rule():
    # 240 rolling-from-the-strike tracks leaving the table (seed 31, every
    # noise level, 0.1-0.3 s seen): gross16's rule refuses none that the
    # seen-time rule keeps (measured 0; the seen-time rule 17, as gross13).
    from cuespin.fit.decide import LEVEL
    n, new = 240, 0
    for tr in leaves_table_tracks(n, 31, preset="case4"):
        m = _recover(tr)
        new += "about as well as rolling" in m.reason
    assert new <= n * LEVEL + 2 * np.sqrt(n * LEVEL * (1 - LEVEL))
    assert new == 0


def test_a_track_starting_after_the_strike_is_degenerate():
    # A track that starts 0.2-20 frames after the strike, with an exposure of
    # half a frame: no frame shows the ball still, t0 trades off against x0
    # and v0 along the path, and the frame straddling the fit's t0 pinned it
    # falsely (realistic H.264 32/31, 32/57: 168 and 17 errors off; measured
    # here on 40 such tracks: 6 answered ok, 36-408 errors off, before the
    # rule; none after).  The paper's rule (fit.decide.strike_in_view) on the
    # frames the fit uses.
    from cuespin.data_gen.sampler import sample_shot
    from cuespin.physics import phases
    from cuespin.recover.simulate import simulate_track
    by_rule = 0
    for k in range(12):
        rng = np.random.default_rng(k)
        shot, p = sample_shot(rng, ("masse", "random", "case3", "case1")[k % 4])
        ph = phases(shot, p)
        fps = (120.0, 240.0, 480.0)[k % 3]
        t_start = shot.t0 + float(rng.uniform(0.2, 20)) / fps
        tr = simulate_track(shot, p, fps, 1e-4, rng, 0.5 / fps, t_start=t_start,
                            t_end=min(ph.t2 + 0.3, ph.t1 + 1.0))
        m = _recover(tr)
        assert m.status == "degenerate", (k, m.status, m.reason)
        # v0 not determined (its reason first), or the strike not in view
        assert m.verdicts.get("v0_determined") is False or m.verdicts.get("strike_seen") is False, m.reason
        by_rule += m.verdicts.get("strike_seen") is False
    assert by_rule >= 1  # the rule, not another, refused some (measured: 1 of these 12, the one ok before)


def test_the_papers_answer_follows_the_fits_verdicts_on_the_trusted_frames():
    # The paper's segmentation takes x0 and the slide's start from every
    # frame, the cue's touched run too; where the fit, on the frames left
    # after it, finds v0 not determined or the strike not in view, the
    # paper's answer is degenerate with the fit's reason (realistic H.264
    # seed 32 shot 0: v0 19% off at 10 of its stated errors; paper11).
    from cuespin.recover.estimate import paper_verdicts
    from cuespin.recover.mle import MLEResult
    from cuespin.recover.paper import PaperResult
    paper = PaperResult("ok", "", "parabola", v0=np.array([1.0, 0.0]), w0=np.array([0.0, 10.0]))
    for verdicts, rolling, refused in (({"v0_determined": False}, False, True),
                                       ({"v0_determined": True, "strike_seen": False}, False, True),
                                       ({"v0_determined": True, "strike_seen": True}, False, False),
                                       ({"slide_hidden": True}, True, True),
                                       ({"slide_hidden": True}, False, False),
                                       ({}, False, False)):
        mle = MLEResult("degenerate" if refused else "ok", "the fit's reason", verdicts=verdicts)
        got = paper_verdicts(paper, mle, rolling, BallParams())
        assert (got.status == "degenerate") == refused, verdicts
        if refused:
            assert got.reason == "the fit's reason" and got.v0 is None
        else:
            assert got is paper


def _rolling_answer(tr):
    """The rolling fit's answer to ``tr`` as if the slip decision had said
    rolling (as on realistic H.264 32/54, slip_lr 6.9 under 9.2)."""
    from cuespin.recover.measurements import build_measurements
    meas = build_measurements(tr.t, tr.xy, np.full(len(tr.t), tr.sigma))
    s = tr.shot
    _, roll = mle_module.fit_models(meas, tr.params, (s.x0, s.t0, s.v0, s.w0), tr.exposure_s)
    return mle_module.result(roll, meas, 0.0, True), mle_module.slide_through_chi2(roll, meas)


def test_a_slide_the_track_does_not_exclude_is_not_answered_rolling(monkeypatch):
    # A slide lasting through every frame answered rolling (as on realistic
    # H.264 32/54: slip_lr 6.9 under 9.2, seen 103 ms, 4 times what the
    # seen-time rule SLIDE_THROUGH_TAU asks; w0 53 stated errors off): the
    # track fits such a slide as well as rolling (there: chi-square -0.75),
    # so the answer is degenerate (fit.decide.slide_through_excluded).
    # Generator tracks leaving the table while sliding, 3e-4 m (8, seed 3:
    # measured 5 refused by this rule, 2 by the seen-time rule, 1 failed).
    tracks = list(leaves_table_tracks(8, 3, sigma_grid=(3e-4,)))
    with monkeypatch.context() as mp:  # without the rule these are ok rolling answers
        mp.setattr(mle_module, "slide_through_excluded", lambda d: Decision(True, d, 0.0))
        before = [_rolling_answer(tr)[0] for tr in tracks]
    by_rule = 0
    for tr, b in zip(tracks, before):
        m, d = _rolling_answer(tr)
        if m.status == "failed":
            continue
        assert m.status == "degenerate" and m.w0 is None and m.verdicts["slide_outlasts"], m.reason
        if "about as well as rolling" in m.reason:
            by_rule += 1
            assert not slide_through_excluded(d) and b.status == "ok", (tr.fps, d, b.reason)
    assert by_rule >= 4
    # The same shots rolling from the strike: a slide through them is excluded
    # (measured on 240 such tracks, seed 31: none refused that the seen-time
    # rule kept; gross16).
    for tr in leaves_table_tracks(8, 3, sigma_grid=(3e-4,), preset="case4"):
        m, d = _rolling_answer(tr)
        if "about as well as rolling" in m.reason:
            raise AssertionError((tr.fps, d, m.reason))


def _outlasting_clip_tracks(n, seed, sigma):
    """``n`` paper case-2 shots at 60 fps whose slide (t1 - t0 >= 1.4 s)
    outlasts the 0.7 s seen after the strike, with H.264-like errors
    correlated in time (recover.simulate.shared_errors), as realistic
    H.264 71/5 (true t1 2.84 s, seen to 0.85 s)."""
    from cuespin.data_gen.sampler import sample_shot
    from cuespin.physics import phases
    from cuespin.recover.mle import model_track
    from cuespin.recover.simulate import SimTrack, shared_errors
    rng = np.random.default_rng(seed)
    while n:
        shot, p = sample_shot(rng, "case2")
        if phases(shot, p).t1 - shot.t0 < 1.4:
            continue
        n -= 1
        t = np.arange(0, np.floor((shot.t0 + 0.7) * 60) + 1) / 60
        yield SimTrack(t, model_track(shot, p, t, 0.0) + sigma * shared_errors(len(t), 60.0, rng), sigma, shot, p,
                       0.0, 60.0)


def _codec_recover(tr):
    return estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s, lossless=False,
                    inter_frame=True, run_paper=False).mle


def _z(tr, m):
    """The ok answer's largest |error| in stated errors, else None."""
    if m.status != "ok" or m.w0 is None:
        return None
    err = np.r_[m.v0 - tr.shot.v0, m.w0 - tr.shot.w0]
    return float(np.max(np.abs(err) / np.r_[m.stderr["v0"], m.stderr["w0"]]))


def test_a_slide_outlasting_the_clip_is_not_answered_as_ended(monkeypatch):
    # Realistic H.264 71/5 (60 fps, true t1 2.84 s, seen 0.71 s after the
    # strike): the correlated end_F (9.4 over 6.9) said sliding ended, the
    # free-slip fit put t1 in view (0.77 s) and answered w0 115 stated errors
    # off; a slide through every frame fitted it about as well (chi-square
    # +1.8 under 9.2).  Here "ended" is forced (the end-F decision patched to
    # the fit's t1 in view) on generator tracks of the same kind at 6e-4 m
    # (seed 2, the first 6 of 16 measured: 3 ok 58-100 errors off before,
    # all 3 refused by this rule; fix71).
    import cuespin.recover.estimate as est_module
    from cuespin.fit.decide import t1_in_view
    monkeypatch.setattr(est_module, "sliding_ended", lambda seg, t, t1_fit=None, friction_known=True, end_F=None:
                        Decision(t1_fit is not None and t1_in_view(t1_fit, t), float("nan"), float("nan")))
    tracks = list(_outlasting_clip_tracks(6, 2, 6e-4))
    with monkeypatch.context() as mp:  # the rule off: main before fix71
        orig = mle_module.slide_through_chi2
        mp.setattr(mle_module, "slide_through_chi2",
                   lambda f, m, *a, **k: orig(f, m, *a, **k) if f.rolling else float("inf"))
        before = [_z(tr, _codec_recover(tr)) for tr in tracks]
    assert sum(z is not None and z > GROSS_Z for z in before) >= 2, before
    by_rule = 0
    for tr in tracks:
        m = _codec_recover(tr)
        z = _z(tr, m)
        assert z is None or z <= GROSS_Z, (z, m.reason)
        if m.verdicts.get("slide_ends") is False:
            by_rule += 1
            assert m.status == "degenerate" and m.w0 is None and m.v0 is not None
            assert "a slide lasting all of it fits the track about as well" in m.reason, m.reason
    assert by_rule >= 2


@pytest.mark.slow
def test_slides_ending_in_view_are_not_refused_as_outlasting():
    # 400 generator slides that end in view (recover.simulate.sliding_tracks,
    # seed 31, independent errors): fix71's rule refuses none (measured: 398
    # free-slip answers asked, 0 refused, the smallest chi-square of a slide
    # through every frame 4.1e5 against the threshold 9.2).  The nominal
    # rate, fit.decide.LEVEL, plus two binomial standard errors would allow 7.
    from cuespin.fit.decide import LEVEL
    from cuespin.recover.simulate import sliding_tracks
    n = 400
    refused = sum(_recover(tr).verdicts.get("slide_ends") is False for tr in sliding_tracks(n, 31))
    assert refused <= n * LEVEL + 2 * np.sqrt(n * LEVEL * (1 - LEVEL))
    assert refused == 0
