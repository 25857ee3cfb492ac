"""cuespin: a billiard ball's initial velocity and spin from video.

The stages install as subpackages of this one name (``cuespin.physics``,
``cuespin.track``, ...); their folders sit at the repository root.  The
Python API (:mod:`cuespin.api`) is re-exported here::

    import cuespin
    result = cuespin.recover_video("shot.avi", "shot.json")
"""

__version__ = "0.2.0"

from cuespin.api import (BallParams, InputError, Scene, Shot, generate, make_scene, read_scene,  # noqa: E402
                         recover_video, render_scene, show, track_dataframe, track_video, write_scene)

__all__ = ["BallParams", "InputError", "Scene", "Shot", "generate", "make_scene", "read_scene", "recover_video",
           "render_scene", "show", "track_dataframe", "track_video", "write_scene", "__version__"]
