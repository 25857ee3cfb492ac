"""A slip too short to see (README known limits): a track answered
"rolling from the strike" states errors that include the slip it cannot
exclude (recover.mle.unseen_slip), so its 95% intervals cover the velocity
and spin at the strike of shots sliding less than a frame; true rolling
shots stay ``ok`` with errors widened by at most what
benchmarks/short_slide.py --null measured."""

import numpy as np
import pytest
from scipy.stats import norm

from cuespin.physics import phases
from cuespin.recover.estimate import estimate
from cuespin.recover.simulate import null_rolling_tracks, short_slip_tracks

NOMINAL = 0.95
# The unseen slip's bound over |v0| on 120 true rolling shots
# (benchmarks/short_slide.py --null 120, seed 5): median 0.025, max 0.210.
MAX_UNSEEN_REL = 0.21


def _recover(tr):
    return estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s, run_paper=False)


def _max_misses(n: int) -> int:
    """Misses allowed at the nominal rate plus two binomial standard errors."""
    return int(n * (1 - NOMINAL) + 2 * np.sqrt(n * NOMINAL * (1 - NOMINAL)))


def _coverage(n: int, seed: int):
    covered, rolling = [], 0
    for tr in short_slip_tracks(n, seed):
        m = _recover(tr).mle
        if m is None or m.status != "ok":
            continue  # degenerate or failed: no interval stated
        rolling += m.model == "rolling"
        err = np.r_[m.v0 - tr.shot.v0, m.w0 - tr.shot.w0]
        se = np.r_[m.stderr["v0"], m.stderr["w0"]]
        covered.append(bool(np.all(np.abs(err) < 1.96 * se)))
    return np.array(covered), rolling


def test_sub_frame_slips_covered():
    covered, rolling = _coverage(9, 11)
    assert rolling >= 3  # the case this is about: slips the track calls rolling
    assert np.sum(~covered) <= _max_misses(len(covered)), covered


@pytest.mark.slow
def test_sub_frame_slips_covered_120():
    covered, rolling = _coverage(120, 12)
    assert rolling >= 20
    assert np.sum(~covered) <= _max_misses(len(covered)), covered


def test_true_rolling_shots_stay_ok_and_useful():
    for tr in null_rolling_tracks(4, 13, fps_grid=(60.0, 120.0, 240.0)):
        m = _recover(tr).mle
        assert m.status == "ok" and m.model == "rolling", m.reason
        speed = float(np.hypot(*tr.shot.v0))
        assert 0 < m.unseen_slip <= MAX_UNSEEN_REL * speed
        assert "unseen" in m.reason
        # The stated v0 error holds the bound at 95% and no more than it
        # plus the rolling fit's own error.
        assert np.all(1.96 * m.stderr["v0"] >= m.unseen_slip * (1 - 1e-9))
        assert np.isfinite(phases(tr.shot, tr.params).t2)


# The paper's rolling-segments answer (case 4, x1 at x0) on slips of 1-8
# frames (short_slip_tracks(160, 22), 60-480 fps, rest in view): main's 37
# ok answers lay 560-85,000 of their stated errors off in v0 (x0's, x2's errors
# alone); with the fit's unseen slip in them the same 37, at most 1.92 off
# (docs/measurements.md, papshort).  The test's tracks: four of them.
PAPER_ROLLING_TRACKS = (11, 19, 22, 23)  # case-4 ok answers on main, 558-6,174 stated errors off in v0
# Every component within the point a correct answer passes with stated
# errors that are its standard deviations (normal, none wider than stated)
# but FAMILY_LEVEL of the time over the test's 16 components (Bonferroni,
# two-sided): 3.42.  The stated errors hold a bound on the unseen slip, so
# the measured spread lies far inside (max 0.60 on these four, 1.92 on the
# 37; RMS z 0.003 on true case 4: papshort).
FAMILY_LEVEL = 0.01
PAPER_ROLLING_Z_MAX = float(norm.isf(FAMILY_LEVEL / (2 * 4 * len(PAPER_ROLLING_TRACKS))))


def test_the_papers_rolling_answer_states_the_unseen_slip():
    want = set(PAPER_ROLLING_TRACKS)
    tracks = [tr for i, tr in enumerate(short_slip_tracks(24, 22, frames=(1.0, 8.0),
                                                         fps_grid=(60.0, 120.0, 240.0, 480.0), to_rest=True))
              if i in want]
    for tr in tracks:
        e = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s)
        p = e.paper
        assert e.mle.model == "rolling" and p.status == "ok", p.reason
        assert np.allclose(p.x1, p.x0)  # the rolling segments: x1 at x0
        z = np.r_[p.v0 - tr.shot.v0, p.w0 - tr.shot.w0] / np.r_[p.stderr["v0"], p.stderr["w0"]]
        assert np.abs(z).max() < PAPER_ROLLING_Z_MAX, (tr.fps, z)


def test_the_papers_rolling_answer_is_refused_where_the_fit_failed():
    # Late review of papshort: the rolling segments' answer (case 4) states
    # the fit's unseen slip; where the fit failed there is none to state, and
    # the answer would give x0's and x2's errors alone.
    from cuespin.physics.motion import BallParams
    from cuespin.recover.estimate import paper_verdicts
    from cuespin.recover.mle import MLEResult
    from cuespin.recover.paper import PaperResult
    paper = PaperResult("ok", "", "line", v0=np.array([1.0, 0.0]), w0=np.array([0.0, 10.0]))
    failed = MLEResult("failed", "the fit did not run: singular matrix")
    got = paper_verdicts(paper, failed, True, BallParams())
    assert got.status == "degenerate" and "not bounded" in got.reason
    assert paper_verdicts(paper, failed, False, BallParams()) is paper  # the sliding segments carry their own
