"""Batch recovery over many videos: local worker processes or a Dask cluster.

One writer (this process) appends each finished video's rows to the results
CSV and flushes them, so a killed run loses only videos in flight.  On a
Dask cluster the videos travel in chunks, one task per chunk (see
:func:`chunk_size`), and each chunk's rows are written as it ends: one task
per video costs the scheduler milliseconds each, and 100,000 of them take
tens of seconds before any worker starts.  A rerun
reads the file back, keeps only videos with a complete set of rows (one per
method; a group cut short by a kill is dropped), rewrites it, and skips
those videos by content hash.  Workers return rows, never raise: a bad video
is a ``failed`` row with its reason.
"""

from __future__ import annotations

import csv
import glob
import hashlib
import math
import os
from pathlib import Path

import numpy as np

VIDEO_EXTENSIONS = (".avi", ".mp4", ".mkv", ".mov", ".m4v")
# Chunks per worker thread: enough that a slow chunk does not leave the other
# threads idle at the end, few enough that the scheduler's per-task cost
# (about 1 ms, benchmarks/dask_batch.py) is shared by many videos.
CHUNKS_PER_THREAD = 4
# Most videos in one chunk: a chunk is also the unit a killed run loses and
# the unit results stream back in.
MAX_CHUNK = 200
METHOD_NAMES = ("paper", "mle")
COLUMNS = ["video", "hash", "method", "status", "reason",
           "v0_x", "v0_y", "w0_x", "w0_y", "se_v0_x", "se_v0_y", "se_w0_x", "se_w0_y",
           "x0_x", "x0_y", "t0", "t1", "t2", "model", "frames", "ok_frames",
           "t_track", "t_fit", "t_recover",
           "truth_v0_x", "truth_v0_y", "truth_w0_x", "truth_w0_y",
           "err_v0_rel", "err_rw0_rel"]


class BatchInputError(Exception):
    """The batch's inputs are unusable (nothing to do); one line."""


def expand_inputs(inputs) -> list[Path]:
    """Videos named by paths, folders (their videos) or glob patterns, sorted, once each."""
    found = []
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            cands = [q for q in p.iterdir() if q.is_file()]
        elif any(ch in str(item) for ch in "*?["):
            cands = [Path(q) for q in glob.glob(str(item), recursive=True)]
        elif p.exists():
            cands = [p]
        else:
            raise BatchInputError(f"no such file, folder or match: {item}")
        found += [q for q in cands if q.suffix.lower() in VIDEO_EXTENSIONS and ".part" not in q.name]
    # The paths as given (made absolute, never resolved): a video's scene is
    # looked for beside the path the user named, a symbolic link included.
    unique = {}
    for q in found:
        unique.setdefault(os.path.normpath(os.path.abspath(q)), q)
    out = [Path(k) for k in sorted(unique)]
    if not out:
        raise BatchInputError("no videos found in the inputs (looked for " + ", ".join(VIDEO_EXTENSIONS) + ")")
    return out


def content_hash(path, chunk=1 << 20) -> str:
    """BLAKE2b-128 of a file's bytes (hex): the same video under any name."""
    h = hashlib.blake2b(digest_size=16)
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def scene_for(video: Path, shared: Path | None) -> Path:
    """The scene file for a video: the shared one, or ``<stem>.json`` beside it."""
    return Path(shared) if shared is not None else video.with_suffix(".json")


def _fmt(x):
    if x is None:
        return ""
    if isinstance(x, float):
        return repr(x) if np.isfinite(x) else ""
    return x


def process_video(video: str, scene_path: str, threaded: bool = True) -> list[dict]:
    """Track and recover one video; one row per method (never raises).

    Parameters
    ----------
    video, scene_path : str
        The video and its scene file.
    threaded : bool
        Let the tracker decode on a second thread; batches of many videos run
        one process per core instead.
    """
    if not threaded:
        # One process per core: keep OpenCV and FFmpeg's decoder to one
        # thread each, or two workers fight over both cores.
        os.environ.setdefault("OPENCV_FFMPEG_CAPTURE_OPTIONS", "threads;1")
        import cv2
        cv2.setNumThreads(1)
    from cuespin.pipeline.run import run_recover
    from cuespin.pipeline.io import InputError, read_scene
    from cuespin.track.tracker import TrackerConfig
    from cuespin.track.video import TrackError

    base = {"video": str(video)}
    try:
        base["hash"] = content_hash(video)
    except OSError as exc:
        return [dict(base, hash="", method=m, status="failed", reason=f"cannot read: {exc}") for m in METHOD_NAMES]
    try:
        scene = read_scene(scene_path)
        result = run_recover(video, scene, config=TrackerConfig(threaded=threaded))
    except (InputError, TrackError) as exc:
        return [dict(base, method=m, status="failed", reason=str(exc)) for m in METHOD_NAMES]
    except Exception as exc:  # a worker must return its rows, whatever happened
        return [dict(base, method=m, status="failed", reason=f"internal error: {exc.__class__.__name__}: {exc}")
                for m in METHOD_NAMES]
    rows = []
    tr, ts = result["track"], result["timing_s"]
    truth = scene.truth
    for m in METHOD_NAMES:
        d = result["methods"].get(m, {})
        row = dict(base, method=m, status=d.get("status", "failed"), reason=d.get("reason", ""),
                   frames=tr["frames"], ok_frames=tr["ok_frames"], model=d.get("model") or d.get("trajectory"),
                   t0=d.get("t0"), t1=d.get("t1"), t2=d.get("t2"),
                   t_track=ts["track"], t_fit=ts["fit"], t_recover=ts["recover"])
        for key in ("v0", "w0", "x0"):
            if d.get(key) is not None:
                row[f"{key}_x"], row[f"{key}_y"] = d[key]
        for key in ("v0", "w0"):
            se = (d.get("stderr") or {}).get(key)
            if se is not None:
                row[f"se_{key}_x"], row[f"se_{key}_y"] = se
        if tr.get("error") and not row["reason"]:
            row["reason"] = tr["error"]
        if truth is not None:
            row["truth_v0_x"], row["truth_v0_y"] = truth.v0
            row["truth_w0_x"], row["truth_w0_y"] = truth.w0
            speed = float(np.hypot(*truth.v0))
            if d.get("v0") is not None and speed > 0:
                row["err_v0_rel"] = float(np.hypot(*(np.array(d["v0"]) - truth.v0)) / speed)
            if d.get("w0") is not None and speed > 0:
                row["err_rw0_rel"] = float(scene.physics.R * np.hypot(*(np.array(d["w0"]) - truth.w0)) / speed)
        rows.append(row)
    return rows


def load_done(out: Path) -> dict[str, list[dict]]:
    """Complete groups of rows already in ``out``, by content hash; rewrites the
    file with only those, so a group cut short by a kill is redone, once."""
    if not out.exists():
        return {}
    groups: dict[str, list[dict]] = {}
    with open(out, newline="") as f:
        for row in csv.DictReader(f):
            if None in row or not row.get("hash") or row.get("method") not in METHOD_NAMES:
                continue  # a line cut short
            g = groups.setdefault(row["hash"], [])
            if all(r["method"] != row["method"] for r in g):
                g.append(row)
    done = {h: g for h, g in groups.items() if len(g) == len(METHOD_NAMES)}
    tmp = out.with_name(out.name + ".part")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        w.writeheader()
        for g in done.values():
            w.writerows(g)
    os.replace(tmp, out)
    return done


def run_batch(videos, out: Path, shared_scene: Path | None = None, workers: int | None = None,
              scheduler: str | None = None, progress=True, chunk: int | None = None) -> dict:
    """Process videos into ``out``, resuming what is already there.

    Returns ``{"done": n, "skipped": n, "failed": n, "rows": n}``; ``failed``
    counts videos whose processing failed outright.
    """
    from tqdm import tqdm

    out = Path(out)
    done = load_done(out)
    todo = []
    for v in videos:  # hashing reads every file: only worth it when resuming
        try:
            h = content_hash(v) if done else None
        except OSError:
            h = None
        if h is None or h not in done:
            todo.append(v)
    skipped = len(videos) - len(todo)
    counts = {"done": 0, "skipped": skipped, "failed": 0, "rows": 0}
    if not todo:
        return counts
    f = open(out, "a", newline="")
    writer = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
    if out.stat().st_size == 0:
        writer.writeheader()
    bar = tqdm(total=len(todo), desc="videos", unit="video", disable=None if progress else True,
               dynamic_ncols=True)

    def emit(rows):
        writer.writerows([{k: _fmt(r.get(k)) for k in COLUMNS} for r in rows])
        f.flush()
        os.fsync(f.fileno())
        counts["done"] += 1
        counts["rows"] += len(rows)
        if all(r["status"] == "failed" for r in rows):
            counts["failed"] += 1
        bar.update(1)
        bar.set_postfix(failed=counts["failed"])

    jobs = [(str(v), str(scene_for(Path(v), shared_scene))) for v in todo]
    try:
        if scheduler:
            _run_dask(jobs, scheduler, emit, chunk)
        else:
            _run_local(jobs, workers or os.cpu_count() or 1, emit)
    finally:
        bar.close()
        f.close()
    return counts


def _run_local(jobs, workers, emit):
    if workers <= 1:
        for v, s in jobs:
            emit(process_video(v, s, False))
        return
    from concurrent.futures import ProcessPoolExecutor, as_completed
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futs = [pool.submit(process_video, v, s, False) for v, s in jobs]
        for fut in as_completed(futs):
            emit(fut.result())


def chunk_size(n_videos: int, n_threads: int, max_chunk: int = MAX_CHUNK) -> int:
    """Videos per Dask task: about ``CHUNKS_PER_THREAD`` chunks per worker thread, at most ``max_chunk``.

    Parameters
    ----------
    n_videos : int
        Videos to process.
    n_threads : int
        Worker threads on the cluster (all workers together).
    max_chunk : int
        Cap on a chunk's size.
    """
    return max(1, min(max_chunk, math.ceil(n_videos / (CHUNKS_PER_THREAD * max(n_threads, 1)))))


def process_chunk(jobs, task=None) -> list[list[dict]]:
    """Process a chunk of ``(video, scene)`` jobs on one worker: each video's rows, in order.

    ``task(video, scene, threaded)`` is :func:`process_video` unless given
    (the benchmark passes a no-op); it never raises.
    """
    task = task or process_video
    return [task(v, s, False) for v, s in jobs]


def _run_dask(jobs, address, emit, chunk: int | None = None, task=None) -> dict:
    """Send ``jobs`` to a Dask cluster in chunks; ``emit`` each video's rows as its chunk ends.

    Returns timings (s): ``first`` (first chunk back, from the call) and
    ``total``, and the ``chunk`` size used.
    """
    import time
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise BatchInputError("--scheduler needs Dask: pip install 'cuespin[dask]'")
    clock = time.perf_counter()
    try:
        client = Client(address, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise BatchInputError(f"cannot reach the Dask scheduler at {address}: {exc}")
    stats = {"first": None}
    try:
        threads = sum(client.nthreads().values()) or 1
        size = chunk or chunk_size(len(jobs), threads)
        chunks = [jobs[i:i + size] for i in range(0, len(jobs), size)]
        # pure=False: a rerun must run again, not reuse a cached result.
        futs = client.map(process_chunk, chunks, task=task, pure=False)
        for fut in as_completed(futs):
            rows = fut.result()
            fut.release()  # the chunk's rows are written: let the cluster forget them
            if stats["first"] is None:
                stats["first"] = time.perf_counter() - clock
            for r in rows:
                emit(r)
    finally:
        client.close()
    stats.update(total=time.perf_counter() - clock, chunk=size)
    return stats
