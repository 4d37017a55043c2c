"""Scene scripts: a Python file defining ``build_scene()`` that returns a :class:`pdsim.Scene`."""

from __future__ import annotations

import importlib.util
import os
import sys

from .errors import ParameterError


def load_scene_script(path: str):
    """Imports a scene script and returns its ``build_scene`` callable."""
    if not path.endswith(".py"):
        raise ParameterError("scene", path, "a Python scene script (*.py)")
    if not os.path.isfile(path):
        raise ParameterError("scene", path, "an existing file")
    folder = os.path.dirname(os.path.abspath(path))
    if folder not in sys.path:  # as when the script runs on its own: its folder's modules import
        sys.path.insert(0, folder)
    spec = importlib.util.spec_from_file_location("pdsim_user_scene", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    build = getattr(module, "build_scene", None)
    if not callable(build):
        raise ParameterError("scene", path, "a script that defines build_scene() returning a pdsim.Scene")
    return build
