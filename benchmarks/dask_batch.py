"""Dask batch scheduling: one task per video against chunks, on a LocalCluster.

Times the batch's own Dask path (``pipeline.batch._run_dask``: connect,
submit, stream results back, one ``emit`` per video) with a no-op in place of
tracking, so what is measured is the scheduling: the overhead per video with
one task per video (``chunk=1``) and with the default chunks, alternated and
repeated (medians; the machine is shared, so compare within the run).  Then
submits 100,000 no-op videos in chunks and times the first result (target:
under 10 s) and the whole.  With ``--real N`` it also renders N tiny videos (a
few frames each) and runs the real batch both ways: the difference per video
is the scheduling overhead with real tasks.

Usage: python benchmarks/dask_batch.py [--n 2000] [--big 100000] [--repeat 3] [--workers 2] [--real 0]
"""

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from cuespin.pipeline.batch import METHOD_NAMES, _run_dask, chunk_size, process_video


def noop(video, scene, threaded):
    """What a worker returns for a video, without touching it."""
    return [{"video": video, "method": m, "status": "ok", "reason": ""} for m in METHOD_NAMES]


def timed(address, jobs, chunk, task):
    got = [0]

    def emit(rows):
        got[0] += 1

    t = time.perf_counter()
    stats = _run_dask(jobs, address, emit, chunk=chunk, task=task)
    total = time.perf_counter() - t
    assert got[0] == len(jobs), (got[0], len(jobs))
    return total, stats


def tiny_videos(folder: Path, n: int):
    """``n`` tiny videos (6 frames of 256 x 128 px) with their scene files."""
    import cuespin
    from cuespin.physics.motion import BallParams, Shot

    jobs = []
    for i in range(n):
        scene = cuespin.make_scene(Shot((0.5, 0.5), (1.0, 0.1 * (i % 5)), (0.0, 0.0), 0.02), BallParams(),
                                   fps=60.0, px_per_m=100.0,
                                   render={"max_duration": 0.09, "codec": "MJPG", "seed": i, "noise_sigma": 2.0})
        v, s = folder / f"t{i:05d}.avi", folder / f"t{i:05d}.json"
        cuespin.write_scene(s, scene)
        cuespin.render_scene(scene, v)
        jobs.append((str(v), str(s)))
    return jobs


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000, help="no-op videos for the overhead comparison")
    ap.add_argument("--big", type=int, default=100_000, help="no-op videos for the time to first result")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2, help="worker processes, one thread each")
    ap.add_argument("--real", type=int, default=0, help="also run N tiny real videos both ways")
    args = ap.parse_args()

    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        addr = cluster.scheduler_address
        jobs = [(f"/videos/shot_{i:06d}.avi", f"/videos/shot_{i:06d}.json") for i in range(args.n)]
        timed(addr, jobs[:50], None, noop)  # warm the workers (imports, connections)
        per = {"one task per video": [], "chunks": []}
        for _ in range(args.repeat):  # alternated, so both see the same load
            per["one task per video"].append(timed(addr, jobs, 1, noop)[0])
            per["chunks"].append(timed(addr, jobs, None, noop)[0])
        size = chunk_size(args.n, args.workers)
        print(f"LocalCluster: {args.workers} workers x 1 thread; {args.n} no-op videos; median of {args.repeat} "
              "alternated runs (connect + submit + stream back + write per video)")
        print("| dispatch | wall (s) | overhead per video (ms) |")
        print("|---|---|---|")
        for k, v in per.items():
            med = statistics.median(v)
            label = k if k != "chunks" else f"chunks of {size} ({-(-args.n // size)} tasks)"
            print(f"| {label} | {med:.2f} | {1000 * med / args.n:.2f} |")
        ratio = statistics.median(per["one task per video"]) / statistics.median(per["chunks"])
        print(f"one task per video / chunks: {ratio:.1f}x")

        big = [(f"/videos/shot_{i:06d}.avi", f"/videos/shot_{i:06d}.json") for i in range(args.big)]
        total, stats = timed(addr, big, None, noop)
        print(f"{args.big} no-op videos in chunks of {stats['chunk']}: first result after {stats['first']:.2f} s "
              f"(target < 10 s), all done in {total:.1f} s ({1000 * total / args.big:.3f} ms per video)")

        if args.real:
            with tempfile.TemporaryDirectory() as tmp:
                t = time.perf_counter()
                real = tiny_videos(Path(tmp), args.real)
                print(f"rendered {args.real} tiny videos in {time.perf_counter() - t:.0f} s")
                runs = {"one task per video": [], "chunks": []}
                for _ in range(max(1, args.repeat - 1)):
                    runs["one task per video"].append(timed(addr, real, 1, process_video)[0])
                    runs["chunks"].append(timed(addr, real, None, process_video)[0])
                a, b = (statistics.median(runs[k]) for k in ("one task per video", "chunks"))
                print(f"{args.real} real tiny videos: one task per video {a:.1f} s, chunks {b:.1f} s; "
                      f"difference {1000 * (a - b) / args.real:.2f} ms per video")


if __name__ == "__main__":
    main()
