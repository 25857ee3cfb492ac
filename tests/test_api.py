"""The Python API (issue 13): import name, functions, the track DataFrame, no import circles."""

import ast
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cuespin
from cuespin.physics.motion import BallParams, Shot, phases
from cuespin.pipeline.run import mark_predictions

ROOT = Path(__file__).resolve().parents[1]


def imported_modules(path: Path) -> set[str]:
    """Every module a file imports, at any depth (function-level imports too)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_library_modules_do_not_import_the_command_line():
    for f in ("batch.py", "experiments.py", "run.py", "show.py", "measure.py", "io.py"):
        assert "cuespin.pipeline.cli" not in imported_modules(ROOT / "pipeline" / f), f
    assert not any(m.startswith("cuespin.pipeline") for f in (ROOT / "data_gen").glob("*.py")
                   for m in imported_modules(f))
    assert not any(m == "cuespin.render.video" for f in (ROOT / "track").glob("*.py") for m in imported_modules(f))
    assert not any(m.startswith("cuespin.pipeline") for f in (ROOT / "cuespin").glob("*io.py")
                   for m in imported_modules(f))


def test_import_cuespin_is_light_and_exports_the_api():
    code = ("import sys, cuespin; print(sorted(m for m in ('cv2', 'matplotlib', 'pandas', 'scipy') "
            "if m in sys.modules)); print(cuespin.__all__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    heavy, names = out.splitlines()
    assert heavy == "[]"
    for name in ("track_video", "recover_video", "read_scene", "write_scene", "render_scene", "generate",
                 "track_dataframe", "show"):
        assert name in names and callable(getattr(cuespin, name))
        assert "Parameters" in getattr(cuespin, name).__doc__  # numpydoc


def test_scene_round_trip(tmp_path):
    scene = cuespin.make_scene(Shot((0.5, 0.4), (1.0, 0.2), (20.0, -30.0), 0.1), fps=60.0)
    cuespin.write_scene(tmp_path / "s.json", scene)
    assert cuespin.read_scene(tmp_path / "s.json") == scene
    (tmp_path / "bad.json").write_text(json.dumps({"camera": {}}))
    with pytest.raises(cuespin.InputError, match="physics"):
        cuespin.read_scene(tmp_path / "bad.json")


def test_track_dataframe_columns_units_and_gaps():
    from cuespin.track.tracker import NO_BALL, OK
    from cuespin.track.video import TrackResult

    scene = cuespin.make_scene(Shot((0.5, 0.4), (1.0, 0.2), (0.0, 0.0), 0.1), fps=60.0, px_per_m=400.0)
    t = np.arange(4) / 60.0
    xy = np.array([[0.5, 0.4], [0.51, 0.4], [np.nan, np.nan], [0.53, 0.41]])
    uv = scene.camera.to_pixels(xy)
    ok = np.isfinite(xy[:, 0])
    se_px = np.where(ok[:, None], 0.02, np.nan) * np.ones((4, 2))
    tr = TrackResult(t=t, uv=uv, xy=xy, ok=ok, status=np.where(ok, OK, NO_BALL).astype(np.int8),
                     stderr_px=se_px, radius_px=11.4, background=None)
    df = cuespin.track_dataframe(tr, scene)
    assert list(df.columns) == ["frame", "t", "u_px", "v_px", "x_m", "y_m", "ok", "status", "stderr_m"]
    assert df["frame"].tolist() == [0, 1, 2, 3] and df["ok"].tolist() == [True, True, False, True]
    assert df["status"].tolist() == ["ok", "ok", "no ball", "ok"]
    # 0.02 px on a 400 px/m top-down camera is 5e-5 m on each axis.
    assert np.allclose(df["stderr_m"][ok], 0.02 / 400.0) and np.isnan(df["stderr_m"][2])
    assert np.isnan(df["x_m"][2]) and np.isclose(df["u_px"][1], uv[1, 0])
    assert np.isnan(cuespin.track_dataframe(tr)["stderr_m"]).all()  # no camera: not stated in metres


def test_predictions_beyond_the_last_frame_are_marked():
    p = BallParams(mu_s=0.2, mu_r=0.01)
    shot = Shot((0.5, 0.4), (1.0, 0.2), (20.0, -30.0), 0.1)
    ph = phases(shot, p)
    m = {"status": "ok", "x0": [0.5, 0.4], "v0": [1.0, 0.2], "w0": [20.0, -30.0], "t0": 0.1,
         "t1": float(ph.t1), "t2": float(ph.t2)}
    methods = mark_predictions({"mle": dict(m), "paper": {"status": "failed", "t0": None}},
                               t_seen=ph.t1 + 0.5, frame_dt=1 / 120, params=p)
    assert methods["mle"]["predicted"] == ["t2", "x2"]
    assert np.allclose(methods["mle"]["x2"], ph.x2) and np.allclose(methods["mle"]["x1"], ph.x1)
    assert methods["paper"]["predicted"] == []
    seen_all = mark_predictions({"mle": dict(m)}, t_seen=ph.t2 + 0.001, frame_dt=1 / 120, params=p)
    assert seen_all["mle"]["predicted"] == []


def test_api_names_survive_importing_every_stage():
    """Importing a subpackage rebinds its name on the package: no API function may share one."""
    code = ("import cuespin, importlib\n"
            "for s in ('physics', 'data_gen', 'render', 'track', 'fit', 'recover', 'pipeline'):\n"
            "    importlib.import_module('cuespin.' + s)\n"
            "import cuespin.render.video, cuespin.recover.api, cuespin.track.video, cuespin.pipeline.show\n"
            "bad = [n for n in cuespin.__all__ if n != '__version__' and not callable(getattr(cuespin, n))]\n"
            "print(bad)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_readable_table_marks_predictions_and_says_when_nothing_answered():
    from cuespin.pipeline.run import format_recover

    result = {"video": "v.avi", "track": {"frames": 100, "ok_frames": 90, "centroid_noise_px": None,
                                          "last_tracked_t": 1.4},
              "methods": {"paper": {"status": "degenerate", "reason": "no rest point in view", "v0": None,
                                    "w0": None, "t0": 0.2, "t1": 0.5, "t2": None, "predicted": []},
                          "mle": {"status": "ok", "reason": "", "model": "full", "v0": [1.0, 0.2],
                                  "w0": [20.0, -30.0], "t0": 0.2, "t1": 0.5, "t2": 14.8,
                                  "stderr": {"v0": [1e-5, 1e-5], "w0": [0.01, 0.01], "t0": 1e-5},
                                  "predicted": ["t2", "x2"]}},
              "best": None, "timing_s": {"track": 1.0, "fit": 0.1, "recover": 0.1}}
    text = format_recover(result)
    assert " 14.800*" in text and "predicted by the fitted model" in text
    assert "best: none (no method answered ok)" in text
    assert "1 std err" in text and "+/-" not in text and "stated error of a centre" in text
    assert "slip fitted" in text and "reason: no rest point in view" in text
