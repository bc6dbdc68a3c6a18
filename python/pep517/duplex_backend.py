"""PEP 517 build backend of `pip install .`: the project's CMake build, packed into a wheel.

It needs nothing beyond the standard library (pyproject.toml requires nothing), so that the
install works offline and in interpreters without setuptools or wheel (pyenv's, for one).
The wheel holds the package duplex as CMake leaves it in <build>/python/duplex.

Settings (environment variables):
  DUPLEX_BUILD_DIR  the CMake build directory (default: build/pip/<python tag> in the source tree;
                    an existing configured build, e.g. `build`, is reused as it is)
  CMAKE_BUILD_PARALLEL_LEVEL  compile jobs (default 2)
  DUPLEX_CMAKE_ARGS  more arguments for the CMake configure step
"""
import base64
import hashlib
import importlib.util
import os
import pathlib
import shlex
import shutil
import subprocess
import sys
import sysconfig
import zipfile

NAME = "duplex"
VERSION = "0.1.0"
SOURCE = pathlib.Path(__file__).resolve().parents[2]


def _tag():
    impl = "cp" if sys.implementation.name == "cpython" else sys.implementation.name
    ver = f"{sys.version_info[0]}{sys.version_info[1]}"
    abi = f"{impl}{ver}{getattr(sys, 'abiflags', '')}"
    plat = sysconfig.get_platform().replace("-", "_").replace(".", "_")
    return f"{impl}{ver}", abi, plat


def _isolated():
    # pip's isolated build environment hides the interpreter's own site-packages.
    purelib = sysconfig.get_paths()["purelib"]
    return not any(os.path.realpath(p) == os.path.realpath(purelib) for p in sys.path if p)


def _check_numpy():
    """Fails early, naming the interpreter, when it lacks NumPy (the module is useless without it)."""
    if importlib.util.find_spec("numpy") is not None or _isolated():
        return
    raise RuntimeError(
        f"duplex needs NumPy, and the interpreter it is being installed for has none: {sys.executable} "
        f"(Python {sys.version.split()[0]}). Install NumPy for it first ({sys.executable} -m pip install numpy), "
        "or install duplex into an interpreter that has NumPy, e.g. a venv made with "
        "`/usr/bin/python3 -m venv --system-site-packages` (Debian: python3-numpy).")


def _metadata():
    readme = (SOURCE / "README.md").read_text(encoding="utf-8")
    return (f"Metadata-Version: 2.1\nName: {NAME}\nVersion: {VERSION}\n"
            "Summary: Two-level ray tracing of dynamic scenes: scene graph, incremental top level, "
            "Open3D-style RaycastingScene\nRequires-Python: >=3.9\nRequires-Dist: numpy\n"
            f"Description-Content-Type: text/markdown\n\n{readme}")


def _dist_info():
    return f"{NAME}-{VERSION}.dist-info"


def get_requires_for_build_wheel(config_settings=None):
    return []


def get_requires_for_build_sdist(config_settings=None):
    return []


def prepare_metadata_for_build_wheel(metadata_directory, config_settings=None):
    _check_numpy()
    d = pathlib.Path(metadata_directory) / _dist_info()
    d.mkdir(parents=True, exist_ok=True)
    (d / "METADATA").write_text(_metadata(), encoding="utf-8")
    return d.name


def _run(cmd):
    print("duplex_backend: " + " ".join(shlex.quote(str(c)) for c in cmd), file=sys.stderr, flush=True)
    subprocess.run([str(c) for c in cmd], check=True, cwd=SOURCE)


def _cached_python(build):
    """The interpreter a configured build folder is for (FindPython's entries), or None."""
    cache = build / "CMakeCache.txt"
    if not cache.exists():
        return None
    found = {}
    for line in cache.read_text(errors="replace").splitlines():
        for key in ("Python_EXECUTABLE:", "_Python_EXECUTABLE:"):
            if line.startswith(key):
                found[key] = line.split("=", 1)[1]
    return found.get("Python_EXECUTABLE:") or found.get("_Python_EXECUTABLE:")


def _build():
    """Configures and builds the target duplex_python; returns the package folder."""
    if shutil.which("cmake") is None:
        raise RuntimeError("duplex: cmake was not found on PATH (Debian: apt-get install cmake ninja-build; "
                           "scripts/setup.sh lists every package the build needs)")
    python = getattr(sys, "_base_executable", None) or sys.executable  # a venv's extension is its base's
    if _isolated():
        python = sys.executable
    tag = "-".join(_tag()[:2])
    build = pathlib.Path(os.environ.get("DUPLEX_BUILD_DIR") or SOURCE / "build" / "pip" / tag)
    if not build.is_absolute():
        build = SOURCE / build
    configured = (build / "CMakeCache.txt").exists()
    cached = _cached_python(build)
    configure = ["cmake", "-S", SOURCE, "-B", build]
    # A folder configured before (by this backend, scripts/test or by hand) keeps its options.
    if not configured:
        configure += ["-DCMAKE_BUILD_TYPE=Release", "-DDUPLEX_BUILD_TESTS=OFF", "-DDUPLEX_BUILD_EXAMPLES=OFF",
                      "-DDUPLEX_BUILD_BENCH=OFF"]
        if shutil.which("ninja"):
            configure += ["-G", "Ninja"]
    if cached is None or os.path.realpath(cached) != os.path.realpath(python):
        configure.append(f"-DPython_EXECUTABLE={python}")
    configure += ["-DDUPLEX_BUILD_PYTHON=ON"] + shlex.split(os.environ.get("DUPLEX_CMAKE_ARGS", ""))
    _run(configure)
    jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL", "2")
    _run(["cmake", "--build", build, "--target", "duplex_python", "-j", jobs])
    package = build / "python" / NAME
    if not any(package.glob("_duplex*")):
        raise RuntimeError(f"duplex: the build left no extension in {package} (is pybind11-dev installed? "
                           f"see {build / 'CMakeCache.txt'})")
    return package


def _record_line(arcname, data):
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{arcname},sha256={digest},{len(data)}"


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    _check_numpy()
    package = _build()
    interp, abi, plat = _tag()
    wheel_name = f"{NAME}-{VERSION}-{interp}-{abi}-{plat}.whl"
    path = pathlib.Path(wheel_directory) / wheel_name
    dist_info = _dist_info()
    records = []
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
        def add(arcname, data):
            z.writestr(arcname, data)
            records.append(_record_line(arcname, data))

        for f in sorted(package.iterdir()):
            if f.is_file() and not f.name.endswith(".pyc"):
                add(f"{NAME}/{f.name}", f.read_bytes())
        add(f"{dist_info}/METADATA", _metadata().encode())
        add(f"{dist_info}/WHEEL", (f"Wheel-Version: 1.0\nGenerator: duplex_backend\nRoot-Is-Purelib: false\n"
                                   f"Tag: {interp}-{abi}-{plat}\n").encode())
        records.append(f"{dist_info}/RECORD,,")
        z.writestr(f"{dist_info}/RECORD", "\n".join(records) + "\n")
    return wheel_name
