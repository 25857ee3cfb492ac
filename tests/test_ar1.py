"""The AR(1) error model's lag-1 correlation: estimated from the first fit's
residuals, whose own lag-1 autocorrelation lies below the errors' (the fit
takes up the slowly varying part of a correlated error); recover.mle
solves for the errors' correlation that shows as much
(ar1_from_residuals, ar1_expected_lag1)."""

import numpy as np
import pytest

from cuespin.data_gen.sampler import sample_shot
from cuespin.recover.estimate import estimate
from cuespin.recover.mle import (_ar1_cov_times, ar1_expected_lag1, ar1_from_residuals, fit_model,
                                 lag1_autocorrelation)
from cuespin.recover.simulate import simulate_track

SIGMA = 1e-4
RHO = 0.67


def short_track(seed, fps=60.0, rho=RHO):
    """A shot sliding (0.7 s) and rolling, cut 1.5 s after the strike: 97 frames at 60 fps."""
    shot, p = sample_shot(7, "random")
    return simulate_track(shot, p, fps, SIGMA, seed, t_end=shot.t0 + 1.5, rho=rho)


def first_fit(tr):
    est = estimate(tr.t, tr.xy, np.full(len(tr.t), tr.sigma), tr.params, tr.exposure_s, run_paper=False)
    fit = fit_model(est.meas, tr.params, (tr.shot.x0, tr.shot.t0, tr.shot.v0, tr.shot.w0), tr.exposure_s, False)
    return est, fit


def test_ar1_covariance_product_is_the_dense_one():
    est, fit = first_fit(short_track(0))
    meas = est.meas
    idx = np.flatnonzero(meas.single)
    frame = np.rint((meas.t_means[idx] - meas.t_means[idx[0]]) * 60.0).astype(int)
    S = np.eye(2 * meas.n)
    for a, i in enumerate(idx):  # rho^|frames apart| between single measurements, each axis
        for b, j in enumerate(idx):
            for d in (0, 1):
                S[2 * i + d, 2 * j + d] = RHO ** abs(frame[a] - frame[b])
    X = np.random.default_rng(0).standard_normal((2 * meas.n, 3))
    assert np.allclose(_ar1_cov_times(meas, X, RHO), S @ X)


def test_expected_residual_autocorrelation_matches_simulation():
    # The residuals of one fit's Jacobian under AR(1) errors, drawn 3,000
    # times: their mean lag-1 autocorrelation against the formula.  The
    # formula is a ratio of expectations, the simulation an expectation of
    # ratios: they differ by O(1/n) (measured: 0.598 against 0.589 at 97
    # measurements, the simulation's own standard error 0.001).
    est, fit = first_fit(short_track(0))
    meas, J = est.meas, fit.jac
    Q = np.linalg.qr(J / np.sqrt(np.sum(J * J, axis=0)))[0]
    L = np.linalg.cholesky(_ar1_cov_times(meas, np.eye(2 * meas.n), RHO))
    rng = np.random.default_rng(1)
    E = L @ rng.standard_normal((2 * meas.n, 3000))
    R = E - Q @ (Q.T @ E)
    mc = np.mean([lag1_autocorrelation(meas, R[:, k].reshape(-1, 2))[0] for k in range(R.shape[1])])
    g = ar1_expected_lag1(meas, J, RHO)
    assert g < RHO - 0.02  # the fit absorbs a visible share
    assert g == pytest.approx(mc, abs=0.012)
    # Independent errors: slightly anti-correlated residuals (the fit's own).
    assert -0.05 < ar1_expected_lag1(meas, J, 0.0) < 0.0
    # And the inverse: the formula's own value maps back to RHO.
    assert ar1_from_residuals(meas, fit, g) == pytest.approx(RHO, abs=2e-3)


def test_ar1_estimate_unbiased_on_short_tracks():
    # 12 short tracks (97 frames) with AR(1) errors of lag-1 0.67.
    # Measured on 40 such tracks: the first fit's residuals' lag-1
    # correlation averaged 0.589 (what the AR(1) model took before), the
    # model's now 0.660, scatter 0.061 per track; so the mean of 12 has a
    # standard error of 0.018 and the allowance is 3 of them (these 12:
    # 0.566 before, 0.636 now).
    raw, fitted = [], []
    for s in range(12):
        tr = short_track(100 + s)
        est, fit = first_fit(tr)
        assert est.decisions["autocorrelated"]
        raw.append(lag1_autocorrelation(est.meas, fit.residuals)[0])
        fitted.append(est.mle.ar1)
    assert np.mean(fitted) == pytest.approx(RHO, abs=0.055)
    assert np.mean(raw) < RHO - 0.04  # what is corrected: measured 0.589 on 40


def test_one_frame_lattice_for_the_fit_and_the_paper():
    # recover.measurements.frame_lattice: the AR(1) lags the MLE's
    # prewhitener and the paper's inputs' covariance both count (a dropped
    # frame a gap of two steps, jitter rounded, a repeated time one step).
    from cuespin.recover.measurements import frame_lattice
    t = np.array([0.0, 1.0, 2.02, 4.0, 5.0, 5.0, 6.0]) / 120.0
    assert frame_lattice(t).tolist() == [0, 1, 2, 4, 5, 6, 7]
    assert frame_lattice(t[:1]).tolist() == [0]
