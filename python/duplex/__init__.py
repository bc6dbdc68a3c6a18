"""Duplex: two-level ray tracing of scenes that change.

duplex.Scene holds an object library, a scene graph and its tracer (queries from NumPy arrays,
edits with commits); duplex.RaycastingScene has the names, arguments and results of Open3D 0.18's
open3d.t.geometry.RaycastingScene on top of it. docs/python.md is the guide.
"""
import sys as _sys


def _import_error(reason):
    return ImportError(
        f"duplex cannot be imported by {_sys.executable} (Python {_sys.version.split()[0]}): {reason}")


def _built_for():
    try:
        from ._build_info import PYTHON_EXECUTABLE, PYTHON_VERSION
        return f"{PYTHON_EXECUTABLE} (Python {PYTHON_VERSION})"
    except ImportError:
        return None


# NumPy is checked before the extension is loaded: without it the extension imports, and only the
# first query would fail, far from the cause.
try:
    import numpy as _np  # noqa: F401
except ImportError as _e:
    _other = _built_for()
    raise _import_error(
        "NumPy is not installed for this interpreter, and duplex passes every array through NumPy. "
        f"Install it (`{_sys.executable} -m pip install numpy`)"
        + (f" or use the interpreter duplex was built for, {_other}" if _other else "") + f" [{_e}]") from None

try:
    from ._duplex import (INVALID_ID, Cancelled, Scene, max_memory, primary_rays, random_rays, run_lighting,
                          run_sensors, set_max_memory)
    from ._duplex import __version__
except ImportError as _e:
    _other = _built_for()
    _built = f"it was built for {_other}" if _other else "no build information was found beside it"
    raise _import_error(
        f"its extension module did not load ({_e}); {_built}. Build it for this interpreter: "
        f"`{_sys.executable} -m pip install .` in the repository, or cmake -DPython_EXECUTABLE={_sys.executable}"
    ) from None

from ._open3d import Array, RaycastingScene  # noqa: E402

__all__ = ["Array", "Cancelled", "INVALID_ID", "RaycastingScene", "Scene", "max_memory", "primary_rays",
           "random_rays", "run_lighting", "run_sensors", "set_max_memory", "__version__"]
