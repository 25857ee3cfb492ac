"""Batch recovery over many videos: local worker processes or a Dask cluster.

One writer (this process) appends each finished video's rows to the results
CSV and flushes them, so a killed run loses only videos in flight.  A rerun
reads the file back, keeps only videos with a complete set of rows (one per
method; a group cut short by a kill is dropped), rewrites it, and skips
those videos by content hash.  Workers return rows, never raise: a bad video
is a ``failed`` row with its reason.
"""

from __future__ import annotations

import csv
import glob
import hashlib
import os
from pathlib import Path

import numpy as np

VIDEO_EXTENSIONS = (".avi", ".mp4", ".mkv", ".mov", ".m4v")
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
    for v in videos:
        try:
            h = content_hash(v)
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
            _run_dask(jobs, scheduler, emit)
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


def _run_dask(jobs, address, emit):
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise BatchInputError("--scheduler needs Dask: pip install 'cuespin[dask]'")
    try:
        client = Client(address, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise BatchInputError(f"cannot reach the Dask scheduler at {address}: {exc}")
    try:
        futs = [client.submit(process_video, v, s, False, pure=False) for v, s in jobs]
        for fut in as_completed(futs):
            emit(fut.result())
    finally:
        client.close()
