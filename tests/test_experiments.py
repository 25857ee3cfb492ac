"""Experiments on a small grid: every trial recorded, charts written."""

import csv

import numpy as np
import pytest

from cuespin.pipeline.experiments import EXPERIMENTS, pareto, run_experiment, shot_pool
from cuespin.physics import phases


def test_pareto_front():
    pts = [(1.0, 0.5), (2.0, 0.1), (3.0, 0.2), (0.5, 1.0), (2.0, 0.5)]
    assert sorted(pareto(pts)) == [0, 1, 3]


def test_shot_pool_is_recoverable_and_seeded():
    pool = shot_pool(5, seed=3)
    assert pool == shot_pool(5, seed=3)
    for shot, p in pool:
        ph = phases(shot, p)
        assert ph.t1 - shot.t0 >= 0.03


# Stability's quick grid runs in test_experiment_resumes.
@pytest.mark.parametrize("name", [e for e in EXPERIMENTS if e != "stability"])
def test_experiment_small(tmp_path, name):
    path = run_experiment(name, tmp_path, n=1, seed=1, workers=2, quick=True, progress=False)
    rows = list(csv.DictReader(open(path)))
    assert rows and all(r["status_mle"] in ("ok", "degenerate", "ambiguous", "failed") for r in rows)
    ok = [r for r in rows if r["status_mle"] == "ok"]
    assert ok, "the MLE answered none of the trials"
    # The MLE's error is of the order of its bound (recorded for the chart).
    for r in ok:
        assert np.isfinite(float(r["crb_v0"]))
        assert float(r["err_v0_mle"]) < 20 * float(r["crb_v0"]) + 1e-4
    pngs = list(tmp_path.glob("*.png"))
    assert len(pngs) == 1 and pngs[0].stat().st_size > 10_000
    assert pngs[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_trial_leaves_no_files(tmp_path, monkeypatch):
    # Each trial renders a video and its truth sidecar to a temporary file;
    # hundreds of trials must not leave hundreds of files behind.
    import tempfile

    from cuespin.pipeline.experiments import specs_noise, trial
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    row = trial(specs_noise(1, seed=1, quick=True)[0])
    assert row["status_mle"] in ("ok", "degenerate", "ambiguous", "failed")
    assert list(tmp_path.iterdir()) == []


def test_charts_from_rows_with_gaps(tmp_path):
    """Charts drawn from rows with cells no method answered ok, a categorical codec
    axis and a setting with no ok answer at all: every chart is written."""
    from cuespin.pipeline.experiments import CHARTS

    rng = np.random.default_rng(5)
    rows = []
    for f, levels in {"noise": ["2.0", "10.0"], "codec": ["MJPG", "FFV1"]}.items():
        for lv in levels:
            for i in range(4):
                r = {"factor": f, "level": lv, "shot": i, "status_paper": "degenerate", "status_mle": "ok",
                     "err_v0_mle": 10 ** rng.normal(-4, 0.2), "err_rw0_mle": 10 ** rng.normal(-3, 0.2),
                     "crb_v0": 1e-4, "crb_rw0": 1e-3, "config": f"{f} {lv}", "t_total": 1.0 + i,
                     "angle": 90.0 * (i % 2), "mag": 1.5, "t1": 0.2}
                rows.append(r)
    for name, chart in CHARTS.items():
        chart(rows, tmp_path)
    pngs = sorted(p.name for p in tmp_path.glob("*.png"))
    assert pngs == ["noise.png", "speed_accuracy.png", "stability.png"]


def test_experiment_resumes(tmp_path):
    """A run cut short after one trial: its row is on disk, and a rerun with the
    same settings runs only the other trial and charts both."""
    from cuespin.pipeline.experiments import read_trials

    path = run_experiment("stability", tmp_path, n=1, seed=1, workers=1, quick=True, progress=False,
                          max_trials=1)
    first = read_trials(path)
    assert len(first) == 1
    run_experiment("stability", tmp_path, n=1, seed=1, workers=1, quick=True, progress=False)
    rows = read_trials(path)
    ids = [r["trial_id"] for r in rows]
    assert sorted(ids) == ["angle=0.0 mag=1.5 shot=0", "angle=90.0 mag=1.5 shot=1"]
    # The first trial is not redone: its row (timings included) is unchanged.
    again = next(r for r in rows if r["trial_id"] == first[0]["trial_id"])
    assert again["t_total"] == first[0]["t_total"] and again["t_render"] == first[0]["t_render"]
    assert all(r["status_mle"] == "ok" for r in rows)
    for r in rows:
        assert float(r["err_v0_mle"]) < 20 * float(r["crb_v0"]) + 1e-4
    assert (tmp_path / "stability.png").stat().st_size > 10_000
    # A third run finds nothing to do; another seed into the same folder is refused.
    run_experiment("stability", tmp_path, n=1, seed=1, workers=1, quick=True, progress=False)
    assert len(read_trials(path)) == 2
    with pytest.raises(ValueError, match="another run"):
        run_experiment("stability", tmp_path, n=1, seed=2, workers=1, quick=True, progress=False)


def test_half_written_row_is_dropped(tmp_path):
    # A run killed mid-write leaves a partial last line: it is not a finished trial.
    from cuespin.pipeline.experiments import read_trials

    path = tmp_path / "trials.csv"
    path.write_text("trial_id,t_total,status_paper,status_mle\na shot=0,1.5,ok,ok\nb shot=1,2.")
    rows = read_trials(path)
    assert [r["trial_id"] for r in rows] == ["a shot=0"] and rows[0]["t_total"] == 1.5


def test_path_view_keeps_pixels_in_place():
    """The cut view maps every table point to the whole-table view's pixel less
    a whole number of 16 px blocks, and holds the ball's path with its pad."""
    from cuespin.physics import positions
    from cuespin.physics.camera import default_camera
    from cuespin.pipeline.experiments import PAD_M, path_camera

    shot, p = shot_pool(1, seed=2)[0]
    end = phases(shot, p).t1 + 0.5
    cam, full = path_camera(shot, p, 240.0, 500.0, end), default_camera(fps=240.0, px_per_m=500.0)
    xy = positions(shot, p, np.linspace(shot.t0, end, 50))
    d = np.asarray(full.to_pixels(xy)) - np.asarray(cam.to_pixels(xy))
    assert np.allclose(d, d[0]) and np.allclose(d[0] % 16, 0)
    uv = np.asarray(cam.to_pixels(xy))
    r = (p.R + PAD_M) * 500.0
    # The pad is kept where the whole-table view has it (the cut stops at its edges).
    left, top = d[0]  # the cut's corner in the whole-table view
    assert ((uv[:, 0] - r >= 0) | (left == 0)).all() and ((uv[:, 1] - r >= 0) | (top == 0)).all()
    assert ((uv[:, 0] + r <= cam.width) | (cam.width + left == full.width)).all()
    assert ((uv[:, 1] + r <= cam.height) | (cam.height + top == full.height)).all()
    assert (uv - p.R * 500.0 >= 0).all() and (uv[:, 0] + p.R * 500 <= cam.width).all()
    assert cam.width * cam.height < full.width * full.height / 2
