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
# The library side lives in pipeline.run; importable from here for older callers.
from cuespin.pipeline.run import format_recover, run_recover

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
    if result.warning:
        print(f"warning: {result.warning}")
    if result.error:
        raise InputError(f"{args.video}: {result.error}; {result.n_frames} frame rows written to {out}")
    return 0


def cmd_recover(args) -> int:
    import json

    from cuespin.pipeline.io import read_scene
    from cuespin.track.video import TrackError

    scene = read_scene(args.scene)
    _check_outputs(args.plot, args.video_out)
    try:
        with _progress(None, f"track {Path(args.video).name}") as bar:
            result, tr = run_recover(args.video, scene, args.method, args.fit_friction, args.refine,
                                     progress=bar.update, return_track=True)
    except TrackError as exc:
        raise InputError(str(exc))
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(format_recover(result, scene.truth, scene.physics))
    if args.plot or args.video_out:
        _draw(args.video, scene, result, tr, args.plot, args.video_out, quiet=args.json)
    if result["track"].get("error"):
        raise InputError(f"{args.video}: {result['track']['error']}")
    return 0


def _check_outputs(*paths):
    for p in paths:
        if p is not None and not Path(p).parent.exists():
            raise InputError(f"output folder does not exist: {Path(p).parent}")


def _draw(video, scene, result, tr, png, video_out, quiet=False):
    from cuespin.pipeline.show import show_shot

    try:
        show_shot(video, scene, png=png, result=result, video_out=video_out, track=tr)
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot draw {video}: {exc}")
    if not quiet:
        print("wrote " + " and ".join(str(p) for p in (png, video_out) if p))


def cmd_show(args) -> int:
    from cuespin.pipeline.io import read_scene
    from cuespin.track.video import TrackError

    scene = read_scene(args.scene)
    if args.output is None and args.video_out is None:
        raise InputError("nothing to write: give -o SHOT.png and/or --video OUT.mp4")
    _check_outputs(args.output, args.video_out)
    try:
        with _progress(None, f"track {Path(args.video).name}") as bar:
            result, tr = run_recover(args.video, scene, progress=bar.update, return_track=True)
    except TrackError as exc:
        raise InputError(str(exc))
    _draw(args.video, scene, result, tr, args.output, args.video_out)
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
        if args.chunk is not None and args.chunk < 1:
            raise InputError("--chunk must be at least 1")
        counts = run_batch(videos, out, Path(args.scene) if args.scene else None, args.workers,
                           args.scheduler, chunk=args.chunk)
    except BatchInputError as exc:
        raise InputError(str(exc))
    print(f"{len(videos)} videos: {counts['done']} processed, {counts['skipped']} already in {args.output}, "
          f"{counts['failed']} failed")
    return min(counts["failed"], 125)


def cmd_experiment(args) -> int:
    from cuespin.pipeline.experiments import run_experiment

    if args.n < 1:
        raise InputError("--n must be at least 1")
    try:
        path = run_experiment(args.name, Path(args.out), args.n, args.seed, args.workers, args.quick)
    except ValueError as exc:  # the folder holds another run's trials
        raise InputError(str(exc)) from None
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
    print(format_recover(result, scene.truth, scene.physics))
    print(f"again, with JSON: cuespin recover {video} --scene {scene_path} --json")
    return 0


RECOVER_EPILOG = """\
JSON (--json), every field in docs/output.md:
  video                   the video's file name
  track.frames, .ok_frames  frames read; frames with the ball found
  track.centroid_noise_px the tracker's stated standard error of a centre, median over frames (px, per axis)
  track.last_tracked_t    time of the last frame with the ball found (s)
  track.contact           {t, kind}: the first contact, after which frames are not used (null: none)
  track.error             present when the video ended early or showed no ball
  track.warning           present when the stated errors are not calibrated for the video (4:1:1, 4:1:0 chroma)
  methods.paper, .mle     status (ok | ambiguous | degenerate | failed), reason (why, when not ok),
                          x0 (m), t0 (s): the strike; v0 (m/s), w0 (rad/s): the answer;
                          t1/x1: sliding ends; t2/x2: the ball stops (s, m);
                          predicted: which of t1, x1, t2, x2 lie after the last frame seen
                          (the fitted model's extrapolation, not seen in the video)
  methods.paper           trajectory (parabola | line), solutions (every consistent [v0, w0]),
                          stderr (1 standard error of v0, w0, delta method)
  methods.mle             stderr (1 standard error of x0, t0, v0, w0), model (full: slip fitted;
                          rolling: no slip seen), slip_lr, chi2_per_dof, dof, hac, rho1, codec_noise_m;
                          unseen_slip (rolling: the largest change of v0, m/s, by a slip too short
                          to see; stderr includes it, reason says so)
  best                    the method to trust (mle before paper, first that is ok); null if none is
  timing_s                track, fit, recover: wall time (s)
"""


def add_demo(sub):
    d = sub.add_parser("demo", help="generate, render, track and recover one shot",
                       description="Generate one curved (masse) shot, render it to video, track it and "
                                   "recover v0 and w0 by both methods, printed beside the truth.")
    d.add_argument("--out", default="cuespin-demo", help="folder for the demo's files (default: %(default)s)")
    d.set_defaults(func=cmd_demo)


def add_render(sub):
    r = sub.add_parser("render", help="render a scene file to a video and its .truth.csv",
                       description="Render SCENE (a scene file with a truth block) to VIDEO; writes "
                                   "<VIDEO without extension>.truth.csv beside it. The codec is the "
                                   "scene's render.codec (MJPG lossy by default; FFV1 lossless).")
    r.add_argument("scene", help="scene file (JSON, docs/conventions.md)")
    r.add_argument("-o", "--output", required=True, help="video file to write, e.g. shot.avi")
    r.set_defaults(func=cmd_render)


def add_track(sub):
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


def add_recover(sub):
    rc = sub.add_parser("recover", help="track a video and recover v0 and w0 (paper and MLE)",
                        formatter_class=argparse.RawDescriptionHelpFormatter, epilog=RECOVER_EPILOG,
                        description="Track VIDEO, then recover the strike (x0, t0), v0 and w0 by the "
                                    "paper's closed form and by a maximum-likelihood fit of the "
                                    "forward model to the time-stamped track, with standard errors. "
                                    "Each method says ok, ambiguous, degenerate or failed, with a "
                                    "reason. Friction comes from the scene unless --fit-friction. "
                                    "Times marked * are after the last frame seen: predicted by the "
                                    "fitted model.")
    rc.add_argument("video", help="video file")
    rc.add_argument("--scene", required=True, help="scene file (JSON) with physics and camera")
    rc.add_argument("--method", choices=("paper", "mle", "all"), default="all",
                    help="which recovery to run (default: %(default)s)")
    rc.add_argument("--json", action="store_true", help="print the JSON object (fields below)")
    rc.add_argument("--fit-friction", action="store_true",
                    help="estimate mu_s and mu_r too (maximum likelihood only)")
    rc.add_argument("--refine", choices=("fit", "moments"), default="fit",
                    help="tracker refinement (default: %(default)s)")
    rc.add_argument("--plot", metavar="PNG", default=None,
                    help="also draw the shot (as cuespin show does) to PNG")
    rc.add_argument("--video", dest="video_out", metavar="OUT.mp4", default=None,
                    help="also write the video with the fit drawn over it")
    rc.set_defaults(func=cmd_recover)


def add_show(sub):
    s = sub.add_parser("show", help="draw one shot: track, fitted paths, x0/x1/x2, v0 and spin, residuals",
                       description="Track and recover VIDEO and draw it: the tracked centres over the "
                                   "video's felt (a median of frames), each method's path from the "
                                   "forward model with its own x0, v0, w0, t0 (sliding solid, rolling "
                                   "dashed, faint after the last frame seen), x0, x1, x2 and any contact "
                                   "marked, v0 and the spin axis as arrows with +/- 2 standard-error "
                                   "wedges, and below, per method, the residuals (track minus "
                                   "prediction) divided by the tracker's stated error against time.")
    s.add_argument("video", help="video file")
    s.add_argument("--scene", required=True, help="scene file (JSON) with physics and camera")
    s.add_argument("-o", "--output", default=None, metavar="SHOT.png", help="picture to write (PNG)")
    s.add_argument("--video", dest="video_out", metavar="OUT.mp4", default=None,
                   help="write the video with the track and fitted paths drawn over it (H.264)")
    s.set_defaults(func=cmd_show)


def add_batch(sub):
    b = sub.add_parser("batch", help="recover every video in folders/globs into one CSV (resumable)",
                       description="Track and recover many videos, one row per video and method in "
                                   "RESULTS.csv. Each video's scene is <stem>.json beside it (beside the "
                                   "path as given: a symbolic link is not followed) unless --scene is "
                                   "given. Rows are written as videos finish; rerunning with the same "
                                   "output skips videos already there (by content hash). A video that "
                                   "cannot be processed becomes a 'failed' row; the exit status is the "
                                   "number of such videos (0: all processed). Columns: docs/output.md.")
    b.add_argument("inputs", nargs="+", metavar="INPUT", help="video files, folders or glob patterns")
    b.add_argument("-o", "--output", required=True, help="results CSV (appended to and resumed)")
    b.add_argument("--scene", default=None, help="one scene file for every video")
    b.add_argument("--workers", type=int, default=None,
                   help="local worker processes, one core each (default: all cores)")
    b.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on a Dask distributed cluster, e.g. tcp://HOST:8786 (needs cuespin[dask]); "
                        "videos go to workers in chunks")
    b.add_argument("--chunk", type=int, default=None,
                   help="videos per Dask task (default: about 4 chunks per worker thread, at most 200)")
    b.set_defaults(func=cmd_batch)


def add_experiment(sub):
    from cuespin.pipeline.experiments import DEFAULT_N, EXPERIMENTS

    e = sub.add_parser("experiment", help="accuracy against noise/speed, failure maps: CSV + PNG charts",
                       description="noise: errors against noise sigma, frame rate, resolution and codec, "
                                   "with the Cramer-Rao bound. speed-accuracy: time per video against "
                                   "error, Pareto front marked. stability: error and failure rate over "
                                   "spin direction and magnitude. Writes OUT/trials.csv and OUT/*.png; "
                                   "every point is a median over N shots with its interquartile range. "
                                   "Each trial is appended to trials.csv as it ends; rerun the same "
                                   "command to finish a cut-short run (only missing trials run).")
    e.add_argument("name", choices=EXPERIMENTS, help="which experiment")
    e.add_argument("--out", required=True, help="output folder")
    e.add_argument("--n", type=int, default=DEFAULT_N, help="shots per setting (default: %(default)s)")
    e.add_argument("--seed", type=int, default=0, help="seed (default: %(default)s)")
    e.add_argument("--workers", type=int, default=None, help="worker processes (default: all cores)")
    e.add_argument("--quick", action="store_true", help="a small grid, for a smoke test")
    e.set_defaults(func=cmd_experiment)


def add_generate(sub):
    from cuespin.data_gen import PRESETS

    g = sub.add_parser("generate", help="write a seeded dataset of videos, scene files and truth",
                       description="Sample N shots from SEED and render each: DIR/shot_NNNN.{avi,json,truth.csv}. "
                                   "The same seed gives the same files; a rerun skips finished shots.")
    g.add_argument("--n", type=int, required=True, help="number of shots")
    g.add_argument("--seed", type=int, default=0, help="dataset seed (default: %(default)s)")
    g.add_argument("--out", required=True, help="output folder (created if absent)")
    g.add_argument("--preset", choices=PRESETS, default=None,
                   help="one kind of shot for all; default: a mix of every preset")
    g.add_argument("--codec", default=None,
                   help="MJPG (default, lossy), FFV1 (lossless) or H264 (lossy, .mp4 files, CRF 20)")
    g.add_argument("--fps", type=float, default=None, help="frame rate; default: sampled from 60-480")
    g.add_argument("--look", choices=("plain", "realistic"), default="plain", help="plain grey or realistic colour scenes")
    g.add_argument("--camera", choices=("topdown", "tilted"), default="topdown", help="top-down or tilted, lens distorted")
    g.set_defaults(func=cmd_generate)


# Each subcommand registers itself by one small function: a new one is one
# function and one line here.
def add_calibrate(sub):
    from cuespin.pipeline.calibrate import add_parser

    add_parser(sub)


SUBCOMMANDS = [add_demo, add_calibrate, add_render, add_generate, add_track, add_recover, add_show, add_batch,
               add_experiment]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="cuespin",
        description="Recover a billiard ball's initial velocity v0 and spin w0 from top-down video. "
                    "Units are SI; files follow docs/conventions.md; output fields: docs/output.md.")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for add in SUBCOMMANDS:
        add(sub)
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
