"""Scene scripts: a Python file defining ``build_scene()`` that returns a :class:`pdsim.Scene`, and the message of an
exception raised by the user's own code (the script, its helper modules, a region function it passes to pdsim)."""

from __future__ import annotations

import importlib.util
import os
import sys
import sysconfig
import traceback

from .errors import ParameterError, PdsimError

EXIT_SCRIPT_ERROR = 2  # exit status of `pdsim run` when the scene script itself raises
_PDSIM_ROOTS = tuple(
    os.path.dirname(os.path.abspath(p))
    for p in (__file__, importlib.util.find_spec("pdsim.kernels").origin)
    if p is not None
)
_LIBRARY_ROOTS = tuple(
    os.path.abspath(p) for p in {sysconfig.get_paths()[k] for k in ("stdlib", "platstdlib", "purelib", "platlib")} if p
)


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


def _is_user_file(filename: str) -> bool:
    """A file of the user's code: a real file outside pdsim, the standard library and installed packages."""
    if not filename or filename.startswith("<"):
        return False
    path = os.path.abspath(filename)
    return not any(path.startswith(root + os.sep) for root in _PDSIM_ROOTS + _LIBRARY_ROOTS)


def _is_pdsim_file(filename: str) -> bool:
    path = os.path.abspath(filename or "")
    return any(path.startswith(root + os.sep) for root in _PDSIM_ROOTS)


def script_error_message(exc: BaseException) -> str | None:
    """The message of an exception raised by the user's code, or None when it is pdsim's (a PdsimError, or an
    exception whose innermost frame of pdsim or user code is pdsim's: a defect to report with its full traceback).

    The message is one line ``pdsim: error in scene script FILE, line N: TYPE: MESSAGE`` (a syntax error: the line
    it is on) followed by the user's own frames of the traceback, innermost last, as Python prints them."""
    if isinstance(exc, PdsimError) or not isinstance(exc, Exception):
        return None
    frames = traceback.extract_tb(exc.__traceback__)
    own = [f for f in frames if _is_user_file(f.filename) or _is_pdsim_file(f.filename)]
    user = [f for f in frames if _is_user_file(f.filename)]
    if isinstance(exc, SyntaxError) and exc.filename and _is_user_file(exc.filename):
        where = f"{exc.filename}, line {exc.lineno}"
        text = (exc.text or "").rstrip("\n")
        detail = f"\n    {text.strip()}" if text.strip() else ""
        return f"pdsim: error in scene script {where}: {type(exc).__name__}: {exc.msg}{detail}"
    if not own or not _is_user_file(own[-1].filename):
        return None
    last = user[-1]
    head = f"pdsim: error in scene script {last.filename}, line {last.lineno}: {type(exc).__name__}: {exc}"
    listing = "".join(traceback.format_list(user)).rstrip("\n")
    return f"{head}\nTraceback of the scene script (most recent call last):\n{listing}"
