"""Batch runs for real: worker processes, a killed run resumed, a Dask cluster."""

import csv
import os
import signal
import subprocess
import sys
import time
from collections import Counter

import pytest

from cuespin.data_gen.dataset import generate_dataset
from cuespin.pipeline.batch import METHOD_NAMES, load_done, run_batch


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    d = tmp_path_factory.mktemp("ds")
    generate_dataset(d, n=5, seed=17, preset="leaves_table", fps=60.0)
    # A corrupt video with a valid scene beside it.
    (d / "broken.avi").write_bytes((d / "shot_0000.avi").read_bytes()[:5000])
    (d / "broken.json").write_bytes((d / "shot_0000.json").read_bytes())
    return d


def rows_of(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "cuespin.pipeline.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=600, **kw)


def test_local_batch_rows_failures_and_exit_status(dataset, tmp_path):
    out = tmp_path / "r.csv"
    res = cli("batch", dataset, "-o", out, "--workers", 2)
    assert res.returncode == 1, res.stderr  # one video failed
    rows = rows_of(out)
    assert Counter(r["method"] for r in rows) == {m: 6 for m in METHOD_NAMES}
    broken = [r for r in rows if r["video"].endswith("broken.avi")]
    assert {r["status"] for r in broken} == {"failed"} and all(r["reason"] for r in broken)
    good = [r for r in rows if not r["video"].endswith("broken.avi")]
    assert all(r["truth_v0_x"] for r in good) and all(r["frames"] for r in good)
    assert any(r["err_v0_rel"] for r in good)
    # Rerun: nothing to do, nothing duplicated.
    again = cli("batch", dataset, "-o", out)
    assert again.returncode == 0 and "0 processed, 6 already" in again.stdout
    assert len(rows_of(out)) == len(rows)


def test_killed_run_resumes_to_exactly_one_row_per_video_and_method(dataset, tmp_path):
    out = tmp_path / "r.csv"
    proc = subprocess.Popen([sys.executable, "-m", "cuespin.pipeline.cli", "batch", str(dataset), "-o", str(out),
                             "--workers", "1"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    deadline = time.time() + 300
    while time.time() < deadline:  # kill once two videos are in
        if out.exists() and len(rows_of(out)) >= 2 * len(METHOD_NAMES):
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    kept = load_done(out)  # what a rerun will keep: complete groups only
    assert 2 <= len(kept) < 6, "the run should have been killed halfway"
    broken_done = any(g[0]["video"].endswith("broken.avi") for g in kept.values())
    res = cli("batch", dataset, "-o", out, "--workers", 2)
    assert res.returncode == (0 if broken_done else 1)  # failures of this run
    assert f"{6 - len(kept)} processed, {len(kept)} already" in res.stdout
    rows = rows_of(out)
    assert Counter((r["hash"], r["method"]) for r in rows) == {(h, m): 1 for h in {r["hash"] for r in rows}
                                                                for m in METHOD_NAMES}
    assert len({r["hash"] for r in rows}) == 6


def test_torn_file_is_repaired(tmp_path):
    out = tmp_path / "r.csv"
    from cuespin.pipeline.batch import COLUMNS
    with open(out, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        w.writerow({"video": "a.avi", "hash": "aa", "method": "paper", "status": "ok"})
        w.writerow({"video": "a.avi", "hash": "aa", "method": "mle", "status": "ok"})
        w.writerow({"video": "b.avi", "hash": "bb", "method": "paper", "status": "ok"})  # mle lost
        f.write("c.avi,cc,pa")  # a line cut short by a kill
    done = load_done(out)
    assert set(done) == {"aa"}
    assert [r["hash"] for r in rows_of(out)] == ["aa", "aa"]


def test_dask_cluster_in_chunks_gives_the_same_rows_and_resumes(dataset, tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    videos = sorted(p for p in dataset.iterdir() if p.suffix == ".avi")[:3]
    local, remote = tmp_path / "local.csv", tmp_path / "dask.csv"
    run_batch(videos, local, workers=1, progress=False)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1")
        # Two videos in chunks of 2 (one task), then all three: only the third is sent.
        first = run_batch(videos[:2], remote, scheduler=cluster.scheduler_address, progress=False, chunk=2)
        again = run_batch(videos, remote, scheduler=cluster.scheduler_address, progress=False, chunk=2)
    assert (first["done"], again["done"], again["skipped"]) == (2, 1, 2)
    key = ("hash", "method")
    a = {tuple(r[k] for k in key): r for r in rows_of(local)}
    b = {tuple(r[k] for k in key): r for r in rows_of(remote)}
    assert a.keys() == b.keys() and len(a) == 3 * len(METHOD_NAMES)
    for k in a:
        for col in ("status", "reason", "v0_x", "v0_y", "w0_x", "w0_y", "se_v0_x", "t0", "t1"):
            assert a[k][col] == b[k][col], (k, col)


def test_bad_batch_input(tmp_path):
    res = cli("batch", tmp_path / "nothing_here", "-o", tmp_path / "r.csv")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    (tmp_path / "empty").mkdir()
    res = cli("batch", tmp_path / "empty", "-o", tmp_path / "r.csv")
    assert res.returncode == 2 and "no videos found" in res.stderr


def test_chunk_size_from_count_and_threads():
    from cuespin.pipeline.batch import MAX_CHUNK, chunk_size
    assert chunk_size(3, 1) == 1                      # few videos: one each, every thread busy
    assert chunk_size(2000, 2) == MAX_CHUNK           # capped
    assert chunk_size(800, 100) == 2                  # ~4 chunks per thread
    assert chunk_size(100_000, 1000) == 25


def test_scene_is_looked_for_beside_the_path_given(dataset, tmp_path):
    """A symbolic link to a video elsewhere, its scene beside the link: batch keeps the link's path."""
    from cuespin.pipeline.batch import expand_inputs
    links, store = tmp_path / "links", tmp_path / "store"  # the store has videos only, no scenes
    links.mkdir()
    store.mkdir()
    (store / "blob.avi").write_bytes((dataset / "shot_0001.avi").read_bytes())
    (links / "mine.avi").symlink_to(store / "blob.avi")
    (links / "mine.json").write_bytes((dataset / "shot_0001.json").read_bytes())
    videos = expand_inputs([links])
    assert videos == [links / "mine.avi"]
    out = tmp_path / "r.csv"
    counts = run_batch(videos, out, workers=1, progress=False)
    rows = rows_of(out)
    assert counts["failed"] == 0 and {r["video"] for r in rows} == {str(links / "mine.avi")}
