"""The per-draw lines of ``benchmarks/calibration.py --clicked`` runs pooled
by mode: per camera the f error, RMS z and coverage; per mode the coverage
with a 95% bootstrap interval over draws (a draw's four components
together), also without draws past |z| 5.

Usage: python benchmarks/clicked_summary.py RUN.txt [RUN.txt ...]
"""
import re
import sys

import numpy as np

LINE = re.compile(r"\s+(\S+) (\S+) shot (\d+): f (\S+)% z (.*)")


def rms(a):
    return float(np.sqrt(np.mean(a**2)))


def boot(z, n=4000):
    """95% interval of the coverage, draws resampled."""
    rng = np.random.default_rng(0)
    inside = np.abs(z) < 1.96
    means = [inside[rng.integers(0, len(inside), len(inside))].mean() for _ in range(n)]
    return np.percentile(means, [2.5, 97.5])


def main(paths):
    rows = {}
    for path in paths:
        for line in open(path):
            m = LINE.match(line)
            if m:
                rows.setdefault((m[1], m[2]), []).append((int(m[3]), float(m[4]), *map(float, m[5].split())))
    by_mode = {}
    for (cam, mode), r in rows.items():
        a = np.array([x[1:] for x in r])
        z = a[:, 1:]
        by_mode.setdefault(mode, []).append(z)
        print(f"{cam} {mode}: {len(a)} draws | f err RMS {rms(a[:, 0]):.2f}% ({a[:, 0].min():+.1f}..{a[:, 0].max():+.1f}%)"
              f" | v0 z RMS {rms(z[:, :2]):.2f}, R w0 {rms(z[:, 2:]):.2f} | cover {np.mean(np.abs(z) < 1.96):.1%}")
    for mode, zs in by_mode.items():
        for label, z in (("", np.concatenate(zs)), (" without draws past |z| 5", None)):
            if z is None:
                z = np.concatenate(zs)
                z = z[np.abs(z).max(axis=1) < 5]
            lo, hi = boot(z)
            print(f"{mode}{label}: {len(z)} draws, cover {np.mean(np.abs(z) < 1.96):.1%} [{lo:.1%}, {hi:.1%}] "
                  f"(draws resampled); v0 z RMS {rms(z[:, :2]):.2f}, R w0 {rms(z[:, 2:]):.2f}")


if __name__ == "__main__":
    main(sys.argv[1:])
