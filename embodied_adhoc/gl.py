"""The OpenGL platform for offscreen MuJoCo rendering, chosen once before ``mujoco`` is imported.

MuJoCo reads ``MUJOCO_GL`` when it is first imported and defaults to GLFW, which needs a display: on a headless
Linux machine rendering then fails (``mujoco.FatalError``) or GLFW warns "DISPLAY missing". Every entry point that
may render (``run``, ``render``, ``trials`` with a MuJoCo backend, the recording scripts) calls
:func:`choose_gl_platform` first. A user's own ``MUJOCO_GL`` (e.g. ``osmesa``) always wins.
"""

from __future__ import annotations

import os
import sys


def choose_gl_platform() -> str | None:
    """Select EGL (``MUJOCO_GL=egl``, ``PYOPENGL_PLATFORM=egl``) on Linux when there is no display and the user set
    no platform; returns the ``MUJOCO_GL`` in effect (None: MuJoCo's own default).

    Call it before ``mujoco`` (or anything importing it) is imported: once MuJoCo is loaded its platform is fixed,
    and this changes nothing (it returns None).
    """
    chosen = os.environ.get("MUJOCO_GL")
    headless = sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    )
    if chosen or not headless:
        return chosen or None
    if "mujoco" in sys.modules:
        return None
    os.environ["MUJOCO_GL"] = "egl"
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    return "egl"
