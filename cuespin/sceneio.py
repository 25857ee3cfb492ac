"""Reading and writing scene files: the one place the JSON is touched.

A neutral module (no stage imports it but through here) so that data_gen,
the command line and the Python API share one reader and writer.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from cuespin.physics.scene import Scene, SceneError, parse_scene, scene_to_dict


class InputError(Exception):
    """Bad input from the user: the message is one line saying what to do."""


def read_scene(path) -> Scene:
    """Read and validate a scene file (CONVENTIONS.md).

    Parameters
    ----------
    path : str or Path
        A JSON scene file.

    Returns
    -------
    Scene
        Physics values the file leaves out (``R``, ``mu_s``, ``mu_r``) take
        the conventions' defaults, said in one line on stderr.

    Raises
    ------
    InputError
        The file is missing, unreadable, not JSON, or breaks the contract;
        the message is one line naming the file and the key.
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
        # Values that move the answer are never assumed silently (issue 12,
        # item 7): a pool ball's R on a 61.5 mm ball moved w0 by 7-9%.
        used = ", ".join(f"{k} = {v:g}" for k, v in scene.defaulted)
        print(f"{path}: not in the scene file, assumed: {used} (set them to your ball and cloth)",
              file=sys.stderr)
    return scene


def write_scene(path, scene: Scene) -> None:
    """Write a scene file atomically (a reader never sees half a file).

    Parameters
    ----------
    path : str or Path
        Where to write the JSON.
    scene : Scene
    """
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(json.dumps(scene_to_dict(scene), indent=2) + "\n")
    os.replace(tmp, path)
