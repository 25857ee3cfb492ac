"""The cuespin command as a user runs it: real processes, real files."""

import json
import subprocess
import sys

import pytest

from tests.test_scene import CONVENTIONS_EXAMPLE


def run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "cuespin.pipeline.cli", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=300)


def write(path, obj):
    path.write_text(obj if isinstance(obj, str) else json.dumps(obj))
    return path


def assert_one_line_error(res, needle):
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], res.stderr
    assert "Traceback" not in res.stderr


def test_render_writes_video_and_truth(tmp_path):
    d = json.loads(json.dumps(CONVENTIONS_EXAMPLE))
    d["camera"]["fps"] = 60.0
    d["render"] = {"duration": 0.5, "codec": "FFV1"}
    scene = write(tmp_path / "s.json", d)
    res = run("render", scene, "-o", tmp_path / "v.avi")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "v.avi").stat().st_size > 0
    lines = (tmp_path / "v.truth.csv").read_text().splitlines()
    assert lines[0] == "frame,t,u_px,v_px,x_m,y_m,uc_px,vc_px" and len(lines) == 31


@pytest.mark.parametrize("content,needle", [
    (None, "scene file not found"),
    ("{not json", "not valid JSON"),
    ({"camera": CONVENTIONS_EXAMPLE["camera"]}, "physics: required key is missing"),
    ({"physics": {"mu_s": 0}, "camera": CONVENTIONS_EXAMPLE["camera"]}, "physics.mu_s: must be > 0"),
    ({"physics": CONVENTIONS_EXAMPLE["physics"], "camera": CONVENTIONS_EXAMPLE["camera"]}, "truth: required key is missing"),
])
def test_render_bad_input_one_line_exit_2(tmp_path, content, needle):
    scene = tmp_path / "s.json"
    if content is not None:
        write(scene, content)
    assert_one_line_error(run("render", scene, "-o", tmp_path / "v.avi"), needle)


def test_render_unknown_codec(tmp_path):
    d = json.loads(json.dumps(CONVENTIONS_EXAMPLE))
    d["render"] = {"codec": "NOPE", "duration": 0.1}
    res = run("render", write(tmp_path / "s.json", d), "-o", tmp_path / "v.avi")
    assert_one_line_error(res, "cannot write codec NOPE")


def test_help_explains():
    res = run("--help")
    assert res.returncode == 0
    for cmd in ("demo", "render", "generate"):
        assert cmd in res.stdout
    assert run().returncode == 2


def test_generate_cli(tmp_path):
    res = run("generate", "--n", 2, "--seed", 3, "--out", tmp_path / "ds", "--preset", "leaves_table",
              "--fps", 60)
    assert res.returncode == 0, res.stderr
    assert "2 written" in res.stdout
    assert sorted(p.name for p in (tmp_path / "ds").iterdir()) == [
        "shot_0000.avi", "shot_0000.json", "shot_0000.truth.csv",
        "shot_0001.avi", "shot_0001.json", "shot_0001.truth.csv"]
    assert_one_line_error(run("generate", "--n", 0, "--out", tmp_path / "x"), "--n must be at least 1")
