"""Batch throughput with 1 worker and with 2, measured in one run.

Generates a dataset of short shots, then times ``run_batch`` over it with one
worker process and with two (fresh output each time, interleaved, best of
N); prints videos per minute for both and their ratio (target >= 1.7 on a
2-core machine).  Each worker is one single-threaded process, so the ratio
measures how the batch scales with cores.  For reference it also times one
process decoding on a second thread, as ``cuespin recover`` does for a
single video: what a batch of one worker would give up by staying on one core.

Usage: python benchmarks/batch.py [--n 12] [--repeat 2]
"""

import argparse
import tempfile
import time
from pathlib import Path


from cuespin.data_gen.dataset import generate_dataset
from cuespin.pipeline.batch import expand_inputs, process_video, run_batch, scene_for


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=12, help="videos")
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        generate_dataset(Path(tmp) / "ds", n=args.n, seed=5, preset="case3", fps=120.0)
        videos = expand_inputs([Path(tmp) / "ds"])
        best = {1: float("inf"), 2: float("inf"), "threaded": float("inf")}
        for r in range(args.repeat):
            for w in (1, 2):
                out = Path(tmp) / f"r{w}_{r}.csv"
                t = time.perf_counter()
                run_batch(videos, out, workers=w, progress=False)
                best[w] = min(best[w], time.perf_counter() - t)
            t = time.perf_counter()
            for v in videos:
                process_video(str(v), str(scene_for(v, None)), threaded=True)
            best["threaded"] = min(best["threaded"], time.perf_counter() - t)
    rate = {w: 60 * len(videos) / best[w] for w in best}
    print(f"{len(videos)} videos: 1 worker {rate[1]:.1f} videos/min, 2 workers {rate[2]:.1f} videos/min, "
          f"ratio {rate[2] / rate[1]:.2f} (target >= 1.7)")
    print(f"reference: one process with a decoding thread {rate['threaded']:.1f} videos/min; "
          f"2 workers / that {rate[2] / rate['threaded']:.2f}")


if __name__ == "__main__":
    main()
