"""`pip install .` as its users run it (ctest: python.pip_install; not a pytest file).

1. A venv with --system-site-packages over the interpreter the build is for: `pip install
   --no-build-isolation <source>` (offline; DUPLEX_BUILD_DIR: the build folder of this ctest run, so
   that only the module's target is brought up to date), then `import duplex` in the venv finds the
   installed package (not the build folder) and a RaycastingScene answers.
2. Another interpreter first on PATH (pyenv's `python3`): if it lacks NumPy, the install must stop
   before building, naming that interpreter and NumPy.

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
            check = run([python, "-c", "import duplex, pathlib; print(pathlib.Path(duplex.__file__).parent); "
                         "s = duplex.RaycastingScene(); g = s.add_triangles([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]); "
                         "print(s.cast_rays([[0.2, 0.2, 1, 0, 0, -1]])['geometry_ids'].tolist() == [g])"],
                        env=env, cwd=tmp)
            assert check.returncode == 0, f"import duplex failed in the venv:\n{check.stderr}"
            where, ok = check.stdout.split()
            assert pathlib.Path(where).is_relative_to(venv), f"imported {where}, not the venv's installed package"
            assert ok == "True", "the installed RaycastingScene missed its triangle"
            print(f"venv: installed and imported from {where}")

    other = shutil.which("python3", path=env.get("PATH"))
    if not other or os.path.realpath(other) == os.path.realpath(sys.executable):
        skipped.append("no other python3 first on PATH")
    elif run([other, "-c", "import numpy"]).returncode == 0:
        skipped.append(f"{other} has NumPy (the refusal is for interpreters without it)")
    else:
        exe = run([other, "-c", "import sys; print(sys.executable)"]).stdout.strip()
        pip = run([other, "-m", "pip", "install", "--no-build-isolation", "--no-index", source], env=env)
        assert pip.returncode != 0, f"{other} has no NumPy, yet pip installed duplex"
        out = pip.stdout + pip.stderr
        assert "needs NumPy" in out and exe in out, f"the refusal does not name NumPy and {exe}:\n{out[-3000:]}"
        print(f"{exe}: refused, naming it and NumPy")
    for s in skipped:
        print("skipped:", s)
    return SKIP if len(skipped) == 2 else 0


if __name__ == "__main__":
    sys.exit(main())
