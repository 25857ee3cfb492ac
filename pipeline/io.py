"""Reading and writing scene files: the one place the JSON is touched."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from cuespin.physics.scene import Scene, SceneError, parse_scene, scene_to_dict


class InputError(Exception):
    """Bad input from the user: the message is one line saying what to do."""


def read_scene(path) -> Scene:
    """Read and validate a scene file; raise :class:`InputError` with one line.

    Physics values the file leaves out (``R``, ``mu_s``, ``mu_r``) take the
    conventions' defaults, said in one line on stderr.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise InputError(f"scene file not found: {path}")
    except (IsADirectoryError, PermissionError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read scene file {path}: {exc.__class__.__name__}")
    try:
        d = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})")
    try:
        scene = parse_scene(d)
    except SceneError as exc:
        raise InputError(f"{path}: {exc}")
    if scene.defaulted:
        # Values that move the answer are never assumed silently (issue 12, item 7).
        used = ", ".join(f"{k} = {v:g}" for k, v in scene.defaulted)
        print(f"{path}: not in the scene file, assumed: {used} (set them to your ball and cloth)",
              file=sys.stderr)
    return scene


def write_scene(path, scene: Scene) -> None:
    """Write a scene file atomically (a reader never sees half a file)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(json.dumps(scene_to_dict(scene), indent=2) + "\n")
    os.replace(tmp, path)
