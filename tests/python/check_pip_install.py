"""`pip install .` as its users run it (ctest: python.pip_install; not a pytest file).

1. A venv with --system-site-packages over the interpreter the build is for: `pip install
   --no-build-isolation <source>` (offline; DUPLEX_BUILD_DIR: the build folder of this ctest run, so
   that only the module's target is brought up to date), then `import duplex` in the venv finds the
   installed package (not the build folder) and a RaycastingScene answers.
2. Another interpreter first on PATH (pyenv's `python3`), in a venv with --system-site-packages over
   it: `pip install` builds the module for that interpreter (its headers; DUPLEX_BUILD_DIR: the same
   build folder, switched to it and back afterwards, so that only the module is compiled twice) and
   `import duplex` there answers a query. When that interpreter has no NumPy (pyenv's has none here,
   and no index is reachable to install one), the install must first stop before building, naming
   the interpreter and NumPy; the venv then sees this interpreter's NumPy (Debian's) through a .pth
   file, which is sound only for the same Python X.Y (one ABI), else that part is skipped.

Usage: python check_pip_install.py SOURCE_DIR BUILD_DIR   (exit 77: skipped, with the reason)
"""
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile

SKIP = 77


def run(cmd, **kw):
    print("+", " ".join(map(str, cmd)), flush=True)
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)


def installed_and_answers(python, env, cwd):
    """Checks that `python` imports duplex from its own site-packages and that a scene answers."""
    check = run([python, "-c", "import duplex, pathlib, sys; print(pathlib.Path(duplex.__file__).parent); "
                 "s = duplex.RaycastingScene(); g = s.add_triangles([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]); "
                 "print(s.cast_rays([[0.2, 0.2, 1, 0, 0, -1]])['geometry_ids'].tolist() == [g])"],
                env=env, cwd=cwd)
    assert check.returncode == 0, f"import duplex failed with {python}:\n{check.stderr}"
    where, ok = check.stdout.split()
    venv = pathlib.Path(python).parents[1]
    assert pathlib.Path(where).is_relative_to(venv), f"imported {where}, not the venv's installed package"
    assert ok == "True", "the installed RaycastingScene missed its triangle"
    return where


def other_interpreter(other, source, build, env):
    """Case 2 of the module's docstring; returns the reasons of what was skipped."""
    info = run([other, "-c", "import sys; print(sys.executable); print('%d.%d' % sys.version_info[:2])"])
    exe, version = info.stdout.split()
    has_numpy = run([other, "-c", "import numpy"]).returncode == 0
    if not has_numpy:
        pip = run([other, "-m", "pip", "install", "--no-build-isolation", "--no-index", source], env=env)
        assert pip.returncode != 0, f"{other} has no NumPy, yet pip installed duplex"
        out = pip.stdout + pip.stderr
        assert "needs NumPy" in out and exe in out, f"the refusal does not name NumPy and {exe}:\n{out[-3000:]}"
        print(f"{exe}: refused without NumPy, naming it and NumPy")
        if version != "%d.%d" % sys.version_info[:2]:
            return [f"{exe} is Python {version}, this NumPy is for {sys.version_info[0]}.{sys.version_info[1]}: "
                    "no NumPy to install duplex for it with"]
    with tempfile.TemporaryDirectory() as tmp:
        venv = pathlib.Path(tmp) / "venv"
        made = run([other, "-m", "venv", "--system-site-packages", venv])
        if made.returncode != 0:
            return [f"{other} -m venv failed: {made.stderr.strip()[-300:]}"]
        python = venv / "bin" / "python"
        if not has_numpy:
            import importlib.metadata
            import numpy
            shelf = pathlib.Path(tmp) / "numpy_only"
            shelf.mkdir()
            (shelf / "numpy").symlink_to(pathlib.Path(numpy.__file__).parent)
            # Its metadata too: pip resolves the wheel's `Requires-Dist: numpy` from it.
            meta = pathlib.Path(importlib.metadata.distribution("numpy")._path)
            (shelf / meta.name).symlink_to(meta)
            site = run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip()
            (pathlib.Path(site) / "duplex_test_numpy.pth").write_text(f"{shelf}\n")
        original = cached_python(build)
        try:
            pip = run([python, "-m", "pip", "install", "--no-build-isolation", "--no-index", source], env=env, cwd=tmp)
            assert pip.returncode == 0, f"pip install into a venv over {exe} failed:\n{pip.stdout[-3000:]}\n{pip.stderr[-3000:]}"
            where = installed_and_answers(python, env, tmp)
            print(f"{exe} (venv): installed and imported from {where}")
        finally:
            if original and os.path.realpath(cached_python(build) or "") != os.path.realpath(original):
                restore = run(["cmake", "-S", source, "-B", build, f"-DPython_EXECUTABLE={original}"])
                restore = restore if restore.returncode else run(["cmake", "--build", build, "--target", "duplex_python"])
                assert restore.returncode == 0, f"could not switch {build} back to {original}:\n{restore.stderr[-2000:]}"
    return []


def cached_python(build):
    """The interpreter the build folder is configured for."""
    cache = pathlib.Path(build) / "CMakeCache.txt"
    if not cache.exists():
        return None
    found = {}
    for line in cache.read_text(errors="replace").splitlines():
        for key in ("Python_EXECUTABLE:", "_Python_EXECUTABLE:"):  # set by hand / found by FindPython
            if line.startswith(key):
                found[key] = line.split("=", 1)[1]
    return found.get("Python_EXECUTABLE:") or found.get("_Python_EXECUTABLE:")


def main():
    source, build = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["DUPLEX_BUILD_DIR"] = str(build)
    skipped = []
    with tempfile.TemporaryDirectory() as tmp:
        venv = pathlib.Path(tmp) / "venv"
        made = run([sys.executable, "-m", "venv", "--system-site-packages", venv])
        if made.returncode != 0:
            skipped.append(f"venv: {sys.executable} -m venv failed (Debian: python3-venv): {made.stderr.strip()[-300:]}")
        else:
            python = venv / "bin" / "python"
            pip = run([python, "-m", "pip", "install", "--no-build-isolation", "--no-index", source], env=env, cwd=tmp)
            assert pip.returncode == 0, f"pip install failed:\n{pip.stdout[-3000:]}\n{pip.stderr[-3000:]}"
            where = installed_and_answers(python, env, tmp)
            print(f"venv: installed and imported from {where}")

    other = shutil.which("python3", path=env.get("PATH"))
    if not other or os.path.realpath(other) == os.path.realpath(sys.executable):
        skipped.append("no other python3 first on PATH")
    else:
        skipped += other_interpreter(pathlib.Path(other), source, build, env)
    for s in skipped:
        print("skipped:", s)
    return SKIP if len(skipped) == 2 else 0  # neither case could run


if __name__ == "__main__":
    sys.exit(main())
