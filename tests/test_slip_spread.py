"""fit.decide.sliding_seen with recover.mle.slip_lr_without_largest: a slip
seen in one measurement alone (one frame, or one rest's mean) is not told
from one error of a few stated sd, which realistic tracks have
(docs/measurements.md, slip2: 5 of the 6 free slips on rolling MJPG seeds
43/45/47 had one measurement carrying 70-100% of the ratio)."""

import numpy as np
import pytest

from cuespin.fit.decide import slip_threshold
from cuespin.recover.estimate import estimate
from cuespin.recover.simulate import null_rolling_tracks, short_slip_tracks
from tests.test_decide import allowed

# A still ball's shared look error on MJPG: its rest's mean 2-4 of one
# frame's sd off across the path (docs/measurements.md, slip45, rest47).
REST_OFF_SD = 2.5


def test_a_slip_carried_by_the_rest_alone_is_not_seen():
    """Rolling shots (the generator's case 4, 60-480 fps) whose frames
    before the strike all share one error of REST_OFF_SD frame sd across
    the path, fitted as a lossy codec's (a rest one measurement): where the
    slip ratio passes its threshold only with the rest's share in it, the
    answer is rolling, stating the gap to the free-slip fit.  On the ratio
    alone (before slip2) every one of the eight was free slip (ratios
    17.9-92.7); with the rule 5 of the 8 are carried by the rest (the other 3
    stay free slip, ratios 12-19 without it: the rest's own stated error,
    the tracker's, is the real owner), so at least 4 asserted."""
    thr = slip_threshold()
    carried = 0
    for tr in null_rolling_tracks(8, 7, sigma_grid=(1e-4,)):
        xy = tr.xy.copy()
        d = np.asarray(tr.shot.v0, float) / np.hypot(*tr.shot.v0)
        xy[tr.t < tr.shot.t0] += REST_OFF_SD * tr.sigma * np.array([-d[1], d[0]])
        est = estimate(tr.t, xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s, run_paper=False,
                       lossless=False)
        assert est.mle.slip_lr > thr  # the situation: the ratio alone would call it free slip
        if est.decisions["sliding_seen"].statistic <= thr:
            carried += 1
            assert est.mle.model == "rolling", est.mle.reason
            # Neither model excluded: the rolling answer's errors hold the gap.
            assert est.mle.verdicts["slip_in_one_measurement"]
    assert carried >= 4


def test_a_refusal_by_the_slip_gap_names_the_slip():
    """Where the gap to the free-slip fit alone leaves v0 undetermined, the
    reason names the slip, not the strike (late review: held-out H.264 48/22,
    the strike in view, read "the strike at t0 is not in view").  A rolling
    generator track's rolling fit, answered with a gap of its whole speed
    (over MAX_REL_STDERR_V0 of it) and without one."""
    from cuespin.recover import mle
    from cuespin.recover.measurements import build_measurements
    tr = next(iter(null_rolling_tracks(1, 7, sigma_grid=(1e-4,))))
    meas = build_measurements(tr.t, tr.xy, np.full(len(tr.t), tr.sigma))
    s = tr.shot
    _, roll = mle.fit_models(meas, tr.params, (s.x0, s.t0, s.v0, s.w0), tr.exposure_s)
    plain = mle.result(roll, meas, 0.0, True)
    assert plain.status == "ok", plain.reason
    v = np.asarray(roll.shot.v0, float)
    got = mle.result(roll, meas, 0.0, True, slip_gap=np.concatenate([v, [0.0, 0.0]]))
    assert got.status == "degenerate"
    assert got.reason.startswith("a slip neither seen nor excluded"), got.reason


# Rolling answers given with the slip gap (fit.decide.slip_in_one_measurement,
# recover.mle.result's slip_gap) on the generator's tracks where the rule
# falls back to them: short slips (short_slip_tracks, 1-8 frames, 60-480
# fps) and true rollers (null_rolling_tracks).  Measured (docs/measurements.md,
# gapcov; short slips seed 31, 1,200 tracks): 73 answers with a gap, 72
# covered in all four components at 95% (1 miss: 1.4%, binomial SE 1.4%);
# without the gap 64 (9 misses).  True rollers seed 32, 800 tracks: 9 with
# a gap, all covered (the unseen slip's errors already hold them).
GAP_MISS_RATE = 1 / 73
SHORT_SLIPS = dict(frames=(1.0, 8.0), fps_grid=(60.0, 120.0, 240.0, 480.0))


def _gap_answers(tracks):
    """All-four 95% coverage of the rolling answers given with a slip gap."""
    covered = []
    for tr in tracks:
        est = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s, run_paper=False)
        m = est.mle
        if m.status != "ok" or est.decided.slip_gap is None:
            continue
        assert m.model == "rolling" and m.verdicts["slip_in_one_measurement"]
        z = np.r_[(m.v0 - tr.shot.v0) / m.stderr["v0"], (m.w0 - tr.shot.w0) / m.stderr["w0"]]
        covered.append(bool(np.all(np.abs(z) < 1.96)))
    return np.array(covered, bool)


def test_answers_with_the_slip_gap_cover():
    # The first 48 of the measured set: 4 answers with a gap (tracks 5, 29,
    # 45, 47), max |z| 0.97.
    covered = _gap_answers(short_slip_tracks(48, 31, **SHORT_SLIPS))
    assert len(covered) >= 4
    assert np.sum(~covered) <= allowed(len(covered), GAP_MISS_RATE), covered


@pytest.mark.slow
def test_answers_with_the_slip_gap_cover_held_out():
    # Fresh seeds: misses within the measured rate plus two binomial SE
    # (which is under the nominal 5%'s own margin: the gap is conservative).
    covered = np.r_[_gap_answers(short_slip_tracks(600, 33, **SHORT_SLIPS)),
                    _gap_answers(null_rolling_tracks(400, 34))]
    assert len(covered) >= 25
    assert np.sum(~covered) <= allowed(len(covered), GAP_MISS_RATE), covered
