"""fit.decide.sliding_seen with recover.mle.slip_lr_without_largest: a slip
seen in one measurement alone (one frame, or one rest's mean) is not told
from one error of a few stated sd, which realistic tracks have
(docs/measurements.md, slip2: 5 of the 6 free slips on rolling MJPG seeds
43/45/47 had one measurement carrying 70-100% of the ratio)."""

import numpy as np

from cuespin.fit.decide import slip_threshold
from cuespin.recover.estimate import estimate
from cuespin.recover.simulate import null_rolling_tracks

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
