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

from pipeline.io import InputError

DEMO_SEED = 20261122


def _progress(total: int, desc: str, unit: str = "frame"):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, disable=None, leave=False, dynamic_ncols=True)


def cmd_render(args) -> int:
    from pipeline.io import read_scene
    from render import render_video, truth_path, video_length
    from render.video import VideoError

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
    from data_gen.dataset import generate_dataset

    if args.n < 1:
        raise InputError("--n must be at least 1")
    summary = generate_dataset(Path(args.out), n=args.n, seed=args.seed, preset=args.preset,
                               codec=args.codec, fps=args.fps, progress=_progress)
    print(f"{summary['written']} written, {summary['skipped']} already there, in {args.out}")
    return 0


def cmd_track(args) -> int:
    from pipeline.io import read_scene
    from track.tracker import TrackerConfig
    from track.video import TrackError, track_video, write_track_csv

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


def cmd_demo(args) -> int:
    from data_gen import sample_scene
    from pipeline.io import write_scene
    from render import render_video, truth_path, video_length

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scene = sample_scene(DEMO_SEED, "masse", fps=240.0, noise=3.0, blur=False)
    scene_path, video = out / "demo.json", out / "demo.avi"
    write_scene(scene_path, scene)
    n = video_length(scene)
    with _progress(n, "render demo") as bar:
        render_video(scene, video, progress=bar.update)
    t = scene.truth
    print(f"demo shot (seed {DEMO_SEED}, masse preset): x0={list(t.x0)} v0={[round(c, 4) for c in t.v0]} m/s "
          f"w0={[round(c, 3) for c in t.w0]} rad/s, t0={t.t0:.4f} s")
    print(f"rendered {n} frames to {video}; scene {scene_path}; truth {truth_path(video)}")
    print("tracking and recovery are not built yet (issues 3 and 4)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cuespin",
        description="Recover a billiard ball's initial velocity v0 and spin w0 from top-down video. "
                    "Units are SI; files follow CONVENTIONS.md.")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    d = sub.add_parser("demo", help="generate, render (and later track and recover) one shot",
                       description="Generate one curved shot, render it and print what was done.")
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

    g = sub.add_parser("generate", help="write a seeded dataset of videos, scene files and truth",
                       description="Sample N shots from SEED and render each: DIR/shot_NNNN.{avi,json,truth.csv}. "
                                   "The same seed gives the same files; a rerun skips finished shots.")
    g.add_argument("--n", type=int, required=True, help="number of shots")
    g.add_argument("--seed", type=int, default=0, help="dataset seed (default: %(default)s)")
    g.add_argument("--out", required=True, help="output folder (created if absent)")
    from data_gen import PRESETS
    g.add_argument("--preset", choices=PRESETS, default=None,
                   help="one kind of shot for all; default: a mix of every preset")
    g.add_argument("--codec", default=None, help="FourCC, e.g. MJPG (default, lossy) or FFV1 (lossless)")
    g.add_argument("--fps", type=float, default=None, help="frame rate; default: sampled from 60-480")
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
