"""The per-draw lines of ``benchmarks/calibration.py --clicked`` runs pooled
by mode: per camera the f error, RMS z and coverage; per mode the coverage
and the RMS z of v0 and R w0, each with a 95% bootstrap interval over
draws (a draw's four components together), also without draws past |z| 5;
split by whether the fit took AR(1) errors (the per-draw ``ar1``).

Usage: python benchmarks/clicked_summary.py RUN.txt [RUN.txt ...]
"""
import re
import sys

import numpy as np

LINE = re.compile(r"\s+(\S+) (\S+) shot (\d+): f (\S+)% z ([-+0-9.\s]+?)(?: ar1 (\S+))?$")


# The fit took AR(1) errors: through a clicked camera mostly the camera's own
# misfit (the exact camera's fit took none on those draws; docs/measurements.md, clicked13).
AR1_SPLIT = 0.5


def rms(a):
    return float(np.sqrt(np.mean(a**2)))


def boot(z, n=4000, stat=lambda z: np.mean(np.abs(z) < 1.96)):
    """95% interval of ``stat`` (default the coverage), draws resampled (a
    draw's components together)."""
    rng = np.random.default_rng(0)
    means = [stat(z[rng.integers(0, len(z), len(z))]) for _ in range(n)]
    return np.percentile(means, [2.5, 97.5])


def main(paths):
    rows = {}
    for path in paths:
        for line in open(path):
            m = LINE.match(line)
            if m:
                rows.setdefault((m[1], m[2]), []).append((int(m[3]), float(m[4]), *map(float, m[5].split()),
                                                          float(m[6]) if m[6] else np.nan))
    by_mode, ar1_by_mode = {}, {}
    for (cam, mode), r in rows.items():
        a = np.array([x[1:] for x in r])
        z = a[:, 1:5]
        by_mode.setdefault(mode, []).append(z)
        ar1_by_mode.setdefault(mode, []).append(a[:, 5])
        print(f"{cam} {mode}: {len(a)} draws | f err RMS {rms(a[:, 0]):.2f}% ({a[:, 0].min():+.1f}..{a[:, 0].max():+.1f}%)"
              f" | v0 z RMS {rms(z[:, :2]):.2f}, R w0 {rms(z[:, 2:]):.2f} | cover {np.mean(np.abs(z) < 1.96):.1%}")
    for mode, zs in by_mode.items():
        for label, z in (("", np.concatenate(zs)), (" without draws past |z| 5", None)):
            if z is None:
                z = np.concatenate(zs)
                z = z[np.abs(z).max(axis=1) < 5]
            lo, hi = boot(z)
            zv, zw = (boot(z, stat=lambda a, c=c: rms(a[:, c])) for c in (slice(0, 2), slice(2, 4)))
            print(f"{mode}{label}: {len(z)} draws, cover {np.mean(np.abs(z) < 1.96):.1%} [{lo:.1%}, {hi:.1%}] "
                  f"(draws resampled); v0 z RMS {rms(z[:, :2]):.2f} [{zv[0]:.2f}, {zv[1]:.2f}], "
                  f"R w0 {rms(z[:, 2:]):.2f} [{zw[0]:.2f}, {zw[1]:.2f}]")
        z, ar1 = np.concatenate(by_mode[mode]), np.concatenate(ar1_by_mode[mode])
        if np.isfinite(ar1).any():
            for label, sel in ((f"AR(1) errors taken (ar1 > {AR1_SPLIT})", ar1 > AR1_SPLIT),
                               (f"the rest (ar1 <= {AR1_SPLIT})", ar1 <= AR1_SPLIT)):
                zs = z[sel & (np.abs(z).max(axis=1) < 5)]
                if len(zs):
                    print(f"  {mode}, {label}, without draws past |z| 5: {len(zs)} draws, cover "
                          f"{np.mean(np.abs(zs) < 1.96):.1%}; v0 z RMS {rms(zs[:, :2]):.2f}, R w0 {rms(zs[:, 2:]):.2f}")


if __name__ == "__main__":
    main(sys.argv[1:])
