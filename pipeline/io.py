"""Scene files for the command line: re-exported from :mod:`cuespin.sceneio`."""

from cuespin.sceneio import InputError, read_scene, write_scene

__all__ = ["InputError", "read_scene", "write_scene"]
