"""End to end on the renderer's realistic top-down table.

Render a shot (``look: realistic``, 120 fps, 1400 x 756 with the rails in
view), find the camera with ``cuespin calibrate --homography`` (automatic),
then track and recover by maximum likelihood through the camera found and
through the exact one; print the corners' error and both answers.

Usage: python benchmarks/calibration_e2e.py [N]
"""

import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from cuespin.data_gen.sampler import make_scene, sample_shot
from cuespin.physics.camera import Camera
from cuespin.physics.motion import Shot
from cuespin.physics.scene import parse_scene, scene_to_dict
from cuespin.pipeline.cli import main as cli
from cuespin.pipeline.run import run_recover
from cuespin.render import render_video

FPS = 120.0


def summary(m, shot):
    status = m["status"] if m["status"] == "ok" else f"{m['status']}: {str(m.get('reason'))[:60]}"
    err = None if m.get("v0") is None else (np.array(m["v0"]) - shot.v0).round(6).tolist()
    se = (m.get("stderr") or {}).get("v0")
    return status, err, se


def one(i, d):
    rng = np.random.default_rng(100 + i)
    _, params = sample_shot(100 + i, "random")
    ang, speed = rng.uniform(-0.4, 0.4), rng.uniform(0.6, 1.1)
    shot = Shot((0.5, 0.35 + 0.3 * rng.uniform()), (speed * np.cos(ang), speed * np.sin(ang)),
                tuple(rng.uniform(-40, 40, 2)), t0=0.1)
    sc = make_scene(shot, params, fps=FPS, render={"look": "realistic", "noise_sigma": 2.0, "codec": "FFV1",
                                                  "seed": i, "max_duration": 2.5})
    # the conventions' top-down camera with the rails in view all round
    sc = replace(sc, camera=Camera(fps=FPS, width=1400, height=756,
                                   homography=((500.0, 0, 60.0), (0, -500.0, 695.0), (0, 0, 1.0))))
    video = d / f"s{i}.avi"
    t = time.time()
    render_video(sc, video)
    t_render = time.time() - t
    (d / f"s{i}.json").write_text(json.dumps(scene_to_dict(sc)))
    cli(["calibrate", str(video), "-o", str(d / f"c{i}.json"), "--homography", "--R", str(params.R),
         "--mu-s", str(params.mu_s), "--mu-r", str(params.mu_r)])
    cal = parse_scene(json.loads((d / f"c{i}.json").read_text()))
    corners = np.array(json.loads((d / f"c{i}.json").read_text())["calibration"]["corners_px"])
    truth = sc.camera.to_pixels(np.array([[0, 0], [2.54, 0], [2.54, 1.27], [0, 1.27]]))
    c_err = float(np.sqrt(np.mean(np.sum((corners - truth) ** 2, axis=1))))
    res = {name: summary(run_recover(video, s, method="mle")["methods"]["mle"], shot)
           for name, s in (("exact", sc), ("calibrated", cal))}
    print(i, f"render {t_render:.0f}s, corners {c_err:.3f} px RMS", res, flush=True)


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    folder = Path(tempfile.mkdtemp())
    for i in range(n):
        one(i, folder)
