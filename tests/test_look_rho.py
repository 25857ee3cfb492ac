"""The track's stated error correlation used by the recovery (issue 10 item 3, issue 11).

A look the ball's model misses adds an error shared by neighbouring frames:
the tracker states it as a factor on every frame's covariance and the lag-1
correlation of the share it adds (track.misfit.look_misfit).  Passed as
``ar1_floor`` (track.misfit.error_ar1: the AR(1) model of the same long-run
variance), the fit is under AR(1) errors of at least that correlation;
without it, the residuals' own lag-1 correlation, biased low by the fit,
states v0 and w0 too small.
"""

import numpy as np
from scipy.signal import lfilter

from cuespin.data_gen.sampler import sample_shot
from cuespin.recover.estimate import estimate
from cuespin.recover.mle import model_track
from cuespin.track.misfit import error_ar1

# The review's case: 240 fps, 120 frames, 0.05 px independent (1e-4 m at
# 500 px/m) plus an AR(1) excess of 3 times its variance, rho 0.9.
FPS, FRAMES, SIGMA_M, EXCESS, RHO = 240.0, 120, 1e-4, 3.0, 0.9
PRESETS = ("random", "case3", "case5")
TRACKS = 60


def _look_tracks(n: int, seed: int):
    """Sliding shots seen from 10 frames before the strike, their centres'
    error independent plus the correlated excess; yields (shot, params, t, xy)."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        shot, params = sample_shot(rng, PRESETS[i % len(PRESETS)])
        t = (np.round(shot.t0 * FPS) - 10 + np.arange(FRAMES)) / FPS
        a = rng.standard_normal((FRAMES, 2))
        a[1:] *= np.sqrt(1.0 - RHO**2)  # stationary AR(1), unit variance
        a = lfilter([1.0], [1.0, -RHO], a, axis=0)
        e = rng.standard_normal((FRAMES, 2)) + np.sqrt(EXCESS) * a
        yield shot, params, t, model_track(shot, params, t, 0.0) + SIGMA_M * e


def _coverage(floor: bool):
    """Fraction of v0's and of w0's (x, y) components inside the MLE's 95%
    interval over the tracks where it saw slip (a rolling answer's errors
    are the unseen slip's), and how many tracks."""
    factor = 1.0 + EXCESS
    z = []
    for shot, params, t, xy in _look_tracks(TRACKS, 5):
        # As pipeline.run passes a track whose look is not the model's.
        est = estimate(t, xy, np.full(len(t), SIGMA_M * np.sqrt(factor)), params, 0.0, lossless=False,
                       run_paper=False, ar1_floor=error_ar1(factor, RHO) if floor else 0.0)
        m = est.mle
        if m.status == "ok" and m.model == "full":
            z.append(np.r_[(m.v0 - shot.v0) / m.stderr["v0"],
                           (np.asarray(m.w0)[:2] - np.asarray(shot.w0)[:2]) / np.asarray(m.stderr["w0"])[:2]])
    inside = np.abs(np.array(z)) < 1.959964
    return inside[:, :2].mean(), inside[:, 2:].mean(), len(z)


def test_error_ar1_matches_long_run_variance():
    assert error_ar1(1.0, 0.9) == 0.0
    assert error_ar1(4.0, 0.0) == 0.0
    # Long-run variance (1 + 3 * 19) / 4 = 14.5 = (1 + r) / (1 - r).
    assert np.isclose(error_ar1(4.0, 0.9), 13.5 / 15.5)


def test_stated_correlation_gives_honest_coverage():
    v, w, n = _coverage(floor=True)
    v_no, w_no, n_no = _coverage(floor=False)
    assert n >= 40 and n_no >= 40, (n, n_no)
    # Two binomial standard errors of 95% over the tracks (a track's two
    # components are correlated: counted as one trial, the wider margin).
    low = 0.95 - 2 * np.sqrt(0.95 * 0.05 / n)
    assert v >= low and w >= low, (v, w, n, low)
    # Without the stated correlation the same tracks under-cover: the test
    # can fail.
    assert v_no < low and w_no < low, (v_no, w_no, n_no, low)
