"""Video helpers shared by the stages that read (track) and write (render) video.

One neutral module, so that neither stage imports the other for them.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading

_quiet_lock = threading.Lock()
_quiet_depth = 0
_quiet_saved: int | None = None


@contextlib.contextmanager
def quiet_native_stderr():
    """Silence what native code (OpenCV's FFmpeg backend) prints to fd 2.

    Some of its messages are written with fprintf and ignore OpenCV's log
    level; the caller reports failures itself, in one line.  Reference
    counted, so the decoder thread and the main thread may both hold it: the
    first in redirects fd 2, the last out restores it.
    """
    global _quiet_depth, _quiet_saved
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):
        yield
        return
    with _quiet_lock:
        if _quiet_depth == 0:
            sys.stderr.flush()
            _quiet_saved = os.dup(fd)
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, fd)
            os.close(devnull)
        _quiet_depth += 1
    try:
        yield
    finally:
        with _quiet_lock:
            _quiet_depth -= 1
            if _quiet_depth == 0:
                os.dup2(_quiet_saved, fd)
                os.close(_quiet_saved)
                _quiet_saved = None
