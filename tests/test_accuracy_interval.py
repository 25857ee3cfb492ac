"""benchmarks/accuracy.py's coverage interval: a miss never narrows it, and
on simulated shots (review 13's boot.py construction) it holds the truth at
about its nominal 95%."""

import numpy as np

from benchmarks.accuracy import coverage_interval


def test_a_miss_widens_the_interval_downwards():
    # The shot bootstrap gave 72.2-100% with 10 shots all covered and
    # 92.5-100% with one component missed (review 13); now 86.7-100% and
    # 82.7-99.7%.
    for shots in (10, 40):
        hit = np.ones((shots, 4), bool)
        lo_all, hi_all = coverage_interval(hit)
        hit[0, 0] = False
        lo_one, _ = coverage_interval(hit)
        hit[0, :] = False
        lo_shot, _ = coverage_interval(hit)
        assert hi_all == 1.0 or np.isclose(hi_all, 1.0)
        assert lo_shot < lo_one < lo_all


def held(shots, reps, seed, pc=0.95):
    """Share of ``reps`` simulated benchmarks whose interval holds the true
    per-component coverage ``pc``: 4 components per shot, v0's and w0's
    errors correlated 0.9 in pairs (boot.py)."""
    from scipy.stats import norm
    rng = np.random.default_rng(seed)
    zc = norm.ppf(0.5 + pc / 2)
    n = 0
    for _ in range(reps):
        e = rng.standard_normal((shots, 2))
        e2 = 0.9 * e + np.sqrt(1 - 0.81) * rng.standard_normal((shots, 2))
        lo, hi = coverage_interval(np.abs(np.c_[e, e2]) < zc)
        n += lo <= pc <= hi
    return n / reps


def test_coverage_interval_holds_the_truth():
    # 1000 simulated benchmarks of 20 shots at 95% per component: the shot
    # bootstrap held the truth on 89.9% (review 13's boot.py); Wilson with
    # the design effect 96.2% here (96.0% at 10 shots, 94.8% at 40;
    # docs/measurements.md "rev13s").  Not under 95% by more than 2
    # binomial standard errors (1.4%), and not merely wide (under 99%).
    h = held(20, 1000, 1)
    assert 0.95 - 2 * np.sqrt(0.95 * 0.05 / 1000) <= h < 0.99, h


def test_an_ok_without_stated_errors_counts_as_missed(capsys):
    # held37: two paper answers ok without stated errors (29% and 12% off in
    # v0) were left out of the paper's coverage (88.9%; 80.0% counted).
    # accuracy.one_shot gives such an answer z = inf in every component; the
    # summary counts its components as missed and says how many there were.
    from benchmarks.accuracy import COMPONENTS, intervals
    rows = [{"i": k, "noise": 1.0, "paper_status": "ok", **{f"paper_z_{c}": 0.5 for c in COMPONENTS}}
            for k in range(2)]
    rows.append({"i": 2, "noise": 1.0, "paper_status": "ok", **{f"paper_z_{c}": np.inf for c in COMPONENTS}})
    intervals(rows, m="paper", n_boot=50)
    out = capsys.readouterr().out
    assert "coverage 8/12" in out and "1 without stated errors" in out, out
