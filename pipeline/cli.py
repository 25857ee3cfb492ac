"""The ``cuespin`` command line.

Every subcommand turns bad input into one line on stderr and exit status 2;
nothing a user can do should produce a traceback.
"""

from __future__ import annotations

import argparse
import os
import sys

# OpenCV and its FFmpeg backend print warnings straight to stderr; the command
# speaks for itself in one line, so silence them before cv2 is imported.
os.environ.setdefault("OPENCV_LOG_LEVEL", "SILENT")
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
from pathlib import Path

from cuespin.pipeline.io import InputError

DEMO_SEED = 20261122


def demo_scene():
    """The demo's shot: side spin bends the slide (about 0.34 s) before it rolls
    to rest on a slow cloth, all in view; 240 fps, noise sigma 3, MJPG."""
    from cuespin.data_gen.sampler import make_scene
    from cuespin.physics.motion import BallParams, Shot

    shot = Shot(x0=(0.5, 0.35), v0=(0.9, 0.25), w0=(30.0, -40.0), t0=0.25)
    return make_scene(shot, BallParams(mu_s=0.2, mu_r=0.02), fps=240.0,
                      render={"noise_sigma": 3.0, "seed": DEMO_SEED, "codec": "MJPG"})


def _progress(total: int, desc: str, unit: str = "frame"):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=None, leave=False, dynamic_ncols=True)


def cmd_render(args) -> int:
    from cuespin.pipeline.io import read_scene
    from cuespin.render import render_video, truth_path, video_length
    from cuespin.render.video import VideoError

    scene = read_scene(args.scene)
    if scene.truth is None:
        raise InputError(f"{args.scene}: truth: required key is missing (render needs the shot to draw)")
    out = Path(args.output)
    if not out.parent.exists():
        raise InputError(f"output folder does not exist: {out.parent}")
    try:
        n = video_length(scene)
        with _progress(n, f"render {out.name}") as bar:
            truth = render_video(scene, out, progress=bar.update)
    except (VideoError, ValueError) as exc:
        raise InputError(str(exc))
    print(f"wrote {out} ({len(truth.t)} frames) and {truth_path(out)}")
    return 0


def cmd_generate(args) -> int:
    from cuespin.data_gen.dataset import generate_dataset

    if args.n < 1:
        raise InputError("--n must be at least 1")
    summary = generate_dataset(Path(args.out), n=args.n, seed=args.seed, preset=args.preset,
                               codec=args.codec, fps=args.fps, progress=_progress, look=args.look,
                               camera=args.camera)
    print(f"{summary['written']} written, {summary['skipped']} already there, in {args.out}")
    return 0


def cmd_track(args) -> int:
    from cuespin.pipeline.io import read_scene
    from cuespin.track.tracker import TrackerConfig
    from cuespin.track.video import TrackError, track_video, write_track_csv

    scene = read_scene(args.scene)
    out = Path(args.output)
    if not out.parent.exists():
        raise InputError(f"output folder does not exist: {out.parent}")
    try:
        with _progress(None, f"track {Path(args.video).name}") as bar:
            result = track_video(args.video, scene, TrackerConfig(refine=args.refine),
                                 progress=bar.update)
    except TrackError as exc:
        raise InputError(str(exc))
    write_track_csv(out, result)
    counts = ", ".join(f"{v} {k}" for k, v in result.status_counts().items())
    print(f"wrote {out}: {result.n_frames} frames ({counts}); centroid noise "
          f"{result.centroid_noise_px:.4f} px")
    if result.error:
        raise InputError(f"{args.video}: {result.error}; {result.n_frames} frame rows written to {out}")
    return 0


def run_recover(video, scene, method="all", fit_friction=False, refine="fit", progress=None,
                return_track=False, config=None):
    """Track a video and recover v0 and w0: the JSON object of CONVENTIONS.md
    (and the TrackResult too, with ``return_track``)."""
    import time

    from cuespin.recover.api import recover_track
    from cuespin.track.tracker import TrackerConfig
    from cuespin.track.video import track_video

    clock = time.perf_counter()
    if config is None:
        config = TrackerConfig(refine=refine)
    tr = track_video(video, scene, config, progress=progress)
    t_track = time.perf_counter() - clock
    cam = scene.camera
    centre = cam.to_table([[cam.width / 2, cam.height / 2]])[0]
    stderr_m = tr.stderr_px / cam.px_per_m(centre)
    out = recover_track(tr.t, tr.xy, tr.ok, stderr_m, scene.physics, cam.exposure_s, method,
                        fit_friction, lossless=tr.lossless)
    noise = tr.centroid_noise_px
    result = {"video": Path(video).name,
              "track": {"frames": int(tr.n_frames), "ok_frames": int(tr.ok.sum()),
                        "centroid_noise_px": noise if noise == noise else None,
                        **({"error": tr.error} if tr.error else {})},
              "methods": out["methods"], "best": out["best"],
              "timing_s": {"track": t_track, **out["timing_s"]}}
    return (result, tr) if return_track else result


def format_recover(result: dict, truth=None) -> str:
    """A readable table of a recover result (and the truth beside it, if known)."""
    def vec(v, nd=4, fmt="f"):
        return "null" if v is None else "[" + ", ".join(f"{c:.{nd}{fmt}}" for c in v) + "]"

    lines = [f"{result['video']}: {result['track']['ok_frames']}/{result['track']['frames']} frames "
             f"tracked, centroid noise "
             f"{result['track']['centroid_noise_px'] or float('nan'):.4f} px"]
    lines.append(f"{'method':6} {'status':10} {'v0 (m/s)':>22} {'w0 (rad/s)':>24}  t0 (s)")
    if truth is not None:
        lines.append(f"{'truth':6} {'':10} {vec(truth.v0):>22} {vec(truth.w0, 2):>24}  {truth.t0:.4f}")
    for name, m in result["methods"].items():
        t0 = m.get("t0")
        lines.append(f"{name:6} {m['status']:10} {vec(m.get('v0')):>22} {vec(m.get('w0'), 2):>24}  "
                     + ("null" if t0 is None else f"{t0:.4f}"))
        if name == "mle" and m.get("stderr", {}).get("v0"):
            se = m["stderr"]
            lines.append(f"{'  +/-':6} {m.get('model') or '':10} {vec(se.get('v0'), 1, 'e'):>22} "
                         f"{vec(se.get('w0'), 1, 'e'):>24}")
        if m["reason"]:
            lines.append(f"{'':6} reason: {m['reason']}")
    lines.append(f"best: {result['best']}; time (s): "
                 + ", ".join(f"{k} {v:.3f}" for k, v in result["timing_s"].items()))
    return "\n".join(lines)


def cmd_recover(args) -> int:
    import json

    from cuespin.pipeline.io import read_scene
    from cuespin.track.video import TrackError

    scene = read_scene(args.scene)
    try:
        with _progress(None, f"track {Path(args.video).name}") as bar:
            result = run_recover(args.video, scene, args.method, args.fit_friction, args.refine,
                                 progress=bar.update)
    except TrackError as exc:
        raise InputError(str(exc))
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(format_recover(result, scene.truth))
    if result["track"].get("error"):
        raise InputError(f"{args.video}: {result['track']['error']}")
    return 0


def cmd_batch(args) -> int:
    from cuespin.pipeline.batch import BatchInputError, expand_inputs, run_batch

    try:
        videos = expand_inputs(args.inputs)
        if args.scene is not None and not Path(args.scene).exists():
            raise InputError(f"scene file not found: {args.scene}")
        out = Path(args.output)
        if not out.parent.exists():
            raise InputError(f"output folder does not exist: {out.parent}")
        counts = run_batch(videos, out, Path(args.scene) if args.scene else None, args.workers,
                           args.scheduler)
    except BatchInputError as exc:
        raise InputError(str(exc))
    print(f"{len(videos)} videos: {counts['done']} processed, {counts['skipped']} already in {args.output}, "
          f"{counts['failed']} failed")
    return min(counts["failed"], 125)


def cmd_experiment(args) -> int:
    from cuespin.pipeline.experiments import run_experiment

    if args.n < 1:
        raise InputError("--n must be at least 1")
    path = run_experiment(args.name, Path(args.out), args.n, args.seed, args.workers, args.quick)
    charts = sorted(p.name for p in Path(args.out).glob("*.png"))
    print(f"wrote {path} and {', '.join(charts)} in {args.out}")
    return 0


def cmd_demo(args) -> int:
    from cuespin.pipeline.io import write_scene
    from cuespin.render import render_video, truth_path, video_length

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scene = demo_scene()
    scene_path, video = out / "demo.json", out / "demo.avi"
    write_scene(scene_path, scene)
    n = video_length(scene)
    with _progress(n, "render demo") as bar:
        render_video(scene, video, progress=bar.update)
    t = scene.truth
    print(f"demo shot: a curved shot with side spin that stops on the table: x0={list(t.x0)} m, "
          f"v0={list(t.v0)} m/s, w0={list(t.w0)} rad/s, t0={t.t0} s")
    print(f"rendered {n} frames to {video}; scene {scene_path}; truth {truth_path(video)}")
    with _progress(n, "track demo") as bar:
        result = run_recover(video, scene, progress=bar.update)
    print(format_recover(result, scene.truth))
    print(f"again, with JSON: cuespin recover {video} --scene {scene_path} --json")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cuespin",
        description="Recover a billiard ball's initial velocity v0 and spin w0 from top-down video. "
                    "Units are SI; files follow CONVENTIONS.md.")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    d = sub.add_parser("demo", help="generate, render, track and recover one shot",
                       description="Generate one curved (masse) shot, render it to video, track it and "
                                   "recover v0 and w0 by both methods, printed beside the truth.")
    d.add_argument("--out", default="cuespin-demo", help="folder for the demo's files (default: %(default)s)")
    d.set_defaults(func=cmd_demo)

    r = sub.add_parser("render", help="render a scene file to a video and its .truth.csv",
                       description="Render SCENE (a scene file with a truth block) to VIDEO; writes "
                                   "<VIDEO without extension>.truth.csv beside it. The codec is the "
                                   "scene's render.codec (MJPG lossy by default; FFV1 lossless).")
    r.add_argument("scene", help="scene file (JSON, CONVENTIONS.md)")
    r.add_argument("-o", "--output", required=True, help="video file to write, e.g. shot.avi")
    r.set_defaults(func=cmd_render)

    t = sub.add_parser("track", help="track the ball through a video: per-frame centroids in px and m",
                       description="Find the ball in every frame of VIDEO (any video OpenCV reads) and "
                                   "write frame,t,u_px,v_px,x_m,y_m,ok to TRACK.csv. Only the scene's "
                                   "physics and camera blocks are used. Frames with no ball, a ball "
                                   "partly out of view or two ball-like blobs get ok=0.")
    t.add_argument("video", help="video file")
    t.add_argument("--scene", required=True, help="scene file (JSON) with physics and camera")
    t.add_argument("-o", "--output", required=True, help="CSV to write")
    t.add_argument("--refine", choices=("fit", "moments"), default="fit",
                   help="sub-pixel refinement: exact disc-model fit (default, at the "
                        "Cramer-Rao bound) or grey-weighted moments (about 2x worse)")
    t.set_defaults(func=cmd_track)

    rc = sub.add_parser("recover", help="track a video and recover v0 and w0 (paper and MLE)",
                        description="Track VIDEO, then recover the strike (x0, t0), v0 and w0 by the "
                                    "paper's closed form and by a maximum-likelihood fit of the "
                                    "forward model to the time-stamped track, with standard errors. "
                                    "Each method says ok, ambiguous, degenerate or failed, with a "
                                    "reason. Friction comes from the scene unless --fit-friction.")
    rc.add_argument("video", help="video file")
    rc.add_argument("--scene", required=True, help="scene file (JSON) with physics and camera")
    rc.add_argument("--method", choices=("paper", "mle", "all"), default="all",
                    help="which recovery to run (default: %(default)s)")
    rc.add_argument("--json", action="store_true", help="print the JSON object of CONVENTIONS.md")
    rc.add_argument("--fit-friction", action="store_true",
                    help="estimate mu_s and mu_r too (maximum likelihood only)")
    rc.add_argument("--refine", choices=("fit", "moments"), default="fit",
                    help="tracker refinement (default: %(default)s)")
    rc.set_defaults(func=cmd_recover)

    b = sub.add_parser("batch", help="recover every video in folders/globs into one CSV (resumable)",
                       description="Track and recover many videos, one row per video and method in "
                                   "RESULTS.csv. Each video's scene is <stem>.json beside it unless --scene "
                                   "is given. Rows are written as videos finish; rerunning with the same "
                                   "output skips videos already there (by content hash). A video that "
                                   "cannot be processed becomes a 'failed' row; the exit status is the "
                                   "number of such videos (0: all processed).")
    b.add_argument("inputs", nargs="+", metavar="INPUT", help="video files, folders or glob patterns")
    b.add_argument("-o", "--output", required=True, help="results CSV (appended to and resumed)")
    b.add_argument("--scene", default=None, help="one scene file for every video")
    b.add_argument("--workers", type=int, default=None, help="local worker processes, one core each (default: all cores)")
    b.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on a Dask distributed cluster, e.g. tcp://HOST:8786 (needs cuespin[dask])")
    b.set_defaults(func=cmd_batch)

    e = sub.add_parser("experiment", help="accuracy against noise/speed, failure maps: CSV + PNG charts",
                       description="noise: errors against noise sigma, frame rate, resolution and codec, "
                                   "with the Cramer-Rao bound. speed-accuracy: time per video against "
                                   "error, Pareto front marked. stability: error and failure rate over "
                                   "spin direction and magnitude. Writes OUT/trials.csv and OUT/*.png.")
    from cuespin.pipeline.experiments import EXPERIMENTS
    e.add_argument("name", choices=EXPERIMENTS, help="which experiment")
    e.add_argument("--out", required=True, help="output folder")
    e.add_argument("--n", type=int, default=4, help="shots per setting (default: %(default)s)")
    e.add_argument("--seed", type=int, default=0, help="seed (default: %(default)s)")
    e.add_argument("--workers", type=int, default=None, help="worker processes (default: all cores)")
    e.add_argument("--quick", action="store_true", help="a small grid, for a smoke test")
    e.set_defaults(func=cmd_experiment)

    g = sub.add_parser("generate", help="write a seeded dataset of videos, scene files and truth",
                       description="Sample N shots from SEED and render each: DIR/shot_NNNN.{avi,json,truth.csv}. "
                                   "The same seed gives the same files; a rerun skips finished shots.")
    g.add_argument("--n", type=int, required=True, help="number of shots")
    g.add_argument("--seed", type=int, default=0, help="dataset seed (default: %(default)s)")
    g.add_argument("--out", required=True, help="output folder (created if absent)")
    from cuespin.data_gen import PRESETS
    g.add_argument("--preset", choices=PRESETS, default=None,
                   help="one kind of shot for all; default: a mix of every preset")
    g.add_argument("--codec", default=None, help="FourCC, e.g. MJPG (default, lossy) or FFV1 (lossless)")
    g.add_argument("--fps", type=float, default=None, help="frame rate; default: sampled from 60-480")
    g.add_argument("--look", choices=("plain", "realistic"), default="plain", help="plain grey or realistic colour scenes")
    g.add_argument("--camera", choices=("topdown", "tilted"), default="topdown", help="top-down or tilted, lens distorted")
    g.set_defaults(func=cmd_generate)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"cuespin {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"cuespin {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
