#!/usr/bin/env python3
"""Contract tests of `mpirun -np N duplex sensor`, run from CTest on this machine (loopback).

A run shared by N ranks writes the files of a one-process run of the same seed, byte for byte;
resuming with another rank count, a rank killed with SIGKILL and a rank that cannot load its scene
behave as docs/distributed.md says.

  mpi_check.py ranks   DUPLEX MPIRUN WITH_MPI DIR   1, 2, 3 ranks x 1, 2 threads (and --per-light): identical files
  mpi_check.py target  DUPLEX MPIRUN WITH_MPI DIR   --target-error stops every rank count at one batch
  mpi_check.py resume  DUPLEX MPIRUN WITH_MPI DIR   2 ranks to a total inside a batch, resumed by 3
  mpi_check.py kill    DUPLEX MPIRUN WITH_MPI DIR   rank 1 killed (SIGKILL), resumed to the same files
  mpi_check.py missing DUPLEX MPIRUN WITH_MPI DIR   one rank's scene does not exist: all end, non-zero
Exit status: 0 pass, 1 fail, 77 skipped (a build without MPI, or no mpirun).
"""
import json
import os
import shutil
import signal
import subprocess
import sys
import time

SKIP = 77


class Failure(Exception):
    pass


def expect(ok, what):
    if not ok:
        raise Failure(what)


# A closed box of six sensors around a point light, a white Lambertian floor that sends light back
# up (paths of several segments), two bands and angular bins: every kind of tally a batch carries.
SCENE = {
    "format": "scene-json-v1",
    "bands": ["blue", "red"],
    "objects": [{"name": "floor",
                 "mesh": {"positions": [-0.9, -0.9, -0.5, 0.9, -0.9, -0.5, 0.9, 0.9, -0.5, -0.9, 0.9, -0.5],
                          "indices": [0, 1, 2, 0, 2, 3]},
                 "material": {"type": "lambertian", "reflectance": [0.8, 0.3]}}],
    "instances": [{"object": "floor", "transform": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]}],
    "lights": [{"type": "point", "position": [0.1, 0.2, -0.3], "power": 7, "spectrum": [1, 2]}],
    "sensors": [],
}
FACES = ["0,0,1,1, 0,1,0,0, -1,0,0,0", "0,0,-1,-1, 0,1,0,0, 1,0,0,0", "1,0,0,0, 0,0,1,1, 0,-1,0,0",
         "1,0,0,0, 0,0,-1,-1, 0,1,0,0", "1,0,0,0, 0,1,0,0, 0,0,1,1", "1,0,0,0, 0,-1,0,0, 0,0,-1,-1"]
for k, face in enumerate(FACES):
    SCENE["sensors"].append({"name": "face%d" % k, "shape": "rectangle", "size": [2, 2], "bins": [4, 3],
                             "two_sided": True, "angular_bins": [3, 2] if k == 4 else None,
                             "transform": [float(x) for x in face.split(",")]})
    if SCENE["sensors"][-1]["angular_bins"] is None:
        del SCENE["sensors"][-1]["angular_bins"]

# Keys of run.json that differ between runs of the same result: time, the processes used, where a
# resumed run started (checked on its own); the sensors' "file" holds the output folder.
VARYING = {"seconds", "rays_per_s", "threads", "ranks", "mpi", "resumed_from"}


def mpi_env():
    env = dict(os.environ)
    if os.geteuid() == 0:  # OpenMPI refuses root unless told
        env["OMPI_ALLOW_RUN_AS_ROOT"] = "1"
        env["OMPI_ALLOW_RUN_AS_ROOT_CONFIRM"] = "1"
    return env


def run(argv, timeout=120, check=True):
    p = subprocess.run(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                       timeout=timeout, env=mpi_env())
    if check and p.returncode != 0:
        raise Failure("%s: exit %d\n%s" % (" ".join(argv), p.returncode, p.stderr))
    return p


def sensor_args(duplex, scene, rays, threads, out, *extra):
    return [duplex, "sensor", "--scene", scene, "--rays", str(rays), "--threads", str(threads), "--out", out,
            "--progress", "none", *extra]


def mpirun(mpi, ranks):
    return [mpi, "--oversubscribe", "-np", str(ranks)]


def compare(a, b, what):
    """Every file of folder a equals b's byte for byte (run.json: all but VARYING and the file paths)."""
    names = sorted(os.listdir(a))
    expect(names == sorted(os.listdir(b)), "%s: files differ: %s vs %s" % (what, names, sorted(os.listdir(b))))
    expect("run_state.bin" in names and "face0.json" in names and "face0.csv" in names, what + ": files missing")
    for name in names:
        if name == "run.json":
            ja, jb = (json.load(open(os.path.join(d, name))) for d in (a, b))
            for j in (ja, jb):
                for key in VARYING:
                    j.pop(key, None)
                for s in j["sensors"]:
                    s.pop("file")
            expect(ja == jb, "%s: run.json differs:\n%s\n%s" % (what, ja, jb))
        else:
            with open(os.path.join(a, name), "rb") as fa, open(os.path.join(b, name), "rb") as fb:
                expect(fa.read() == fb.read(), "%s: %s differs" % (what, name))


def report(out):
    return json.load(open(os.path.join(out, "run.json")))


def check_ranks(duplex, mpi, d, scene):
    # 300,000 rays: four full batches of 65,536 and a shorter last one, dealt over one or two rounds.
    one = os.path.join(d, "one")
    run(sensor_args(duplex, scene, 300000, 2, one))
    for ranks in (1, 2, 3):
        for threads in (1, 2):
            out = os.path.join(d, "r%d_t%d" % (ranks, threads))
            p = run(mpirun(mpi, ranks) + sensor_args(duplex, scene, 300000, threads, out))
            expect(p.stdout.count("\n") == 1, "%d ranks: stdout is not rank 0's one report line:\n%s" % (ranks, p.stdout))
            r = json.loads(p.stdout)
            expect(r["ranks"] == ranks and r["mpi"]["batches"] == 5 and r["mpi"]["ranks"] == ranks,
                   "%d ranks: report %s" % (ranks, r))
            compare(one, out, "%d ranks x %d threads vs one process" % (ranks, threads))
    # Ranks of different speeds (2, 1 and 1 threads): they trace different shares, same files.
    out = os.path.join(d, "mixed")
    run([mpi, "--oversubscribe", "-np", "1"] + sensor_args(duplex, scene, 300000, 2, out) +
        [":", "-np", "2"] + sensor_args(duplex, scene, 300000, 1, out))
    compare(one, out, "3 ranks with 2, 1 and 1 threads vs one process")
    # Another batch size: another grouping of the sums, the same for any rank count.
    one_b = os.path.join(d, "one_b")
    run(sensor_args(duplex, scene, 300000, 1, one_b, "--batch-rays", "40000"))
    out = os.path.join(d, "r3_b")
    run(mpirun(mpi, 3) + sensor_args(duplex, scene, 300000, 2, out, "--batch-rays", "40000"))
    expect(report(out)["mpi"]["batches"] == 8 and report(out)["batch_rays"] == 40000, "--batch-rays: %s" % report(out))
    compare(one_b, out, "--batch-rays 40000, 3 ranks vs one process")
    print("1, 2, 3 ranks x 1, 2 threads, ranks of 2, 1 and 1 threads, and --batch-rays 40000 with 3 ranks: every "
          "file identical to the one-process run: ok")
    # --per-light with a CIE sky and its sun beside the point light, an illuminance and a luminance
    # meter: the per-light sums travel with the batches, so 3 ranks write the one-process files.
    daylight = dict(SCENE)
    daylight["lights"] = SCENE["lights"] + [
        {"type": "sky", "name": "day", "model": "clear", "zenith_radiance": 2, "spectrum": [1, 1],
         "sun": {"altitude": 50, "azimuth": 100, "normal_irradiance": 4}, "centre": [0, 0, 0], "radius": 2}]
    daylight["meters"] = [{"name": "floor", "points": [[0, 0, -0.45], [0.5, 0.3, -0.45]], "normal": [0, 0, 1]},
                          {"name": "eye", "points": [[0, 0, 0.5]], "normal": [0, 0, -1], "half_angle": 20}]
    daylight_scene = os.path.join(d, "daylight.json")
    with open(daylight_scene, "w") as f:
        json.dump(daylight, f)
    one_l = os.path.join(d, "one_light")
    run(sensor_args(duplex, daylight_scene, 300000, 2, one_l, "--per-light"))
    out = os.path.join(d, "r3_light")
    run(mpirun(mpi, 3) + sensor_args(duplex, daylight_scene, 300000, 1, out, "--per-light"))
    compare(one_l, out, "--per-light with a sky and meters, 3 ranks vs one process")
    r = report(out)
    expect([l["name"] for l in r["lights"]] == ["lights/0", "day", "day/sun"] and len(r["meters"]) == 2 and
           len(r["meters"][1]["lights"]) == 3 and r["meters"][0]["lights"][1]["irradiance_w_m2"][0] > 0,
           "--per-light under mpirun: run.json lights and meters %s %s" % (r["lights"], r["meters"]))
    print("--per-light with a CIE sky, its sun and meters, 3 ranks: every file identical to the one-process run: ok")


def check_target(duplex, mpi, d, scene):
    args = ("--target-error", "0.004", "--target-sensor", "face4")
    one = os.path.join(d, "one")
    run(sensor_args(duplex, scene, 50000000, 2, one, *args))
    r = report(one)
    expect(r["status"] == "target_reached" and r["rays"] % 65536 == 0 and r["rays"] > 2 * 65536,
           "one process: %s" % r)
    for ranks in (2, 3):
        out = os.path.join(d, "r%d" % ranks)
        run(mpirun(mpi, ranks) + sensor_args(duplex, scene, 50000000, 1, out, *args))
        expect(report(out)["status"] == "target_reached", "%d ranks: %s" % (ranks, report(out)))
        compare(one, out, "--target-error with %d ranks" % ranks)
    print("--target-error: 1 process, 2 and 3 ranks stop after batch %d: ok" % (r["rays"] // 65536))


def check_resume(duplex, mpi, d, scene):
    straight = os.path.join(d, "straight")
    run(sensor_args(duplex, scene, 300000, 2, straight))
    out = os.path.join(d, "resumed")
    # 140,000 rays end inside the third batch: its sums are saved open, and rank 0 finishes it alone.
    run(mpirun(mpi, 2) + sensor_args(duplex, scene, 140000, 1, out))
    expect(report(out)["rays"] == 140000, "first part: %s" % report(out))
    run(mpirun(mpi, 3) + sensor_args(duplex, scene, 300000, 1, out, "--resume"))
    expect(report(out)["resumed_from"] == 140000, "resume: %s" % report(out))
    compare(straight, out, "2 ranks to 140,000 rays, resumed by 3 ranks")
    # And the other way: one process to 200,000, two ranks to the end.
    out2 = os.path.join(d, "resumed2")
    run(sensor_args(duplex, scene, 200000, 1, out2))
    run(mpirun(mpi, 2) + sensor_args(duplex, scene, 300000, 2, out2, "--resume"))
    compare(straight, out2, "one process to 200,000 rays, resumed by 2 ranks")
    print("resume with another rank count (2 -> 3 ranks, 1 process -> 2 ranks): same files: ok")


def rank_pid(mpirun_pid, rank):
    """The pid of the given rank among mpirun's descendants (by its OMPI_COMM_WORLD_RANK)."""
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            env = open("/proc/%s/environ" % pid, "rb").read().split(b"\0")
            cmd = open("/proc/%s/cmdline" % pid, "rb").read()
        except OSError:
            continue
        if b"sensor" in cmd and ("OMPI_COMM_WORLD_RANK=%d" % rank).encode() in env:
            # A rank of this mpirun: its parent chain reaches mpirun_pid.
            p = pid
            while p not in ("0", "1"):
                if p == str(mpirun_pid):
                    return int(pid)
                try:
                    p = open("/proc/%s/stat" % p).read().rsplit(")", 1)[1].split()[1]
                except OSError:
                    break
    return None


def check_kill(duplex, mpi, d, scene):
    out = os.path.join(d, "killed")
    err_path = os.path.join(d, "killed.err")
    args = mpirun(mpi, 2) + [duplex, "sensor", "--scene", scene, "--rays", "2000000000", "--threads", "1", "--out",
                             out, "--progress", "lines", "--checkpoint", "0.05"]
    with open(err_path, "w") as err:
        p = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=err, env=mpi_env())
        killed = None
        deadline = time.time() + 60
        while time.time() < deadline and p.poll() is None:
            if open(err_path).read().count("checkpoint: ") >= 2:
                killed = rank_pid(p.pid, 1)
                if killed:
                    os.kill(killed, signal.SIGKILL)
                    break
            time.sleep(0.01)
        try:
            p.wait(timeout=60)
        except subprocess.TimeoutExpired:
            p.kill()
            raise Failure("the job did not end after rank 1 was killed")
    err = open(err_path).read()
    expect(killed is not None, "rank 1 was never found to kill:\n" + err)
    expect(p.returncode != 0, "killed rank: mpirun exited 0")
    expect("rank 1" in err and ("signal 9" in err or "Killed" in err),
           "killed rank: no message naming rank 1 and its signal:\n" + err)
    # The last checkpoint intact, no result files written (a save cut short leaves its temporary
    # file beside the state, never a damaged state).
    left = sorted(set(os.listdir(out)) - {"run_state.bin.tmp"})
    expect(left == ["run_state.bin"], "after the kill: %s" % sorted(os.listdir(out)))
    saved = int(err[err.rfind("checkpoint: ") + len("checkpoint: "):].split()[0])
    total = saved + 1000000
    run(mpirun(mpi, 2) + sensor_args(duplex, scene, total, 1, out, "--resume"))
    expect(report(out)["resumed_from"] >= saved and report(out)["status"] == "completed", "resume: %s" % report(out))
    straight = os.path.join(d, "straight")
    run(sensor_args(duplex, scene, total, 2, straight))
    compare(straight, out, "rank 1 killed, resumed from the last checkpoint")
    print("rank 1 killed with SIGKILL: job ends (exit %d), checkpoint at %d rays intact, resumed: same files: ok"
          % (p.returncode, saved))


def check_missing(duplex, mpi, d, scene):
    out = os.path.join(d, "missing")
    absent = os.path.join(d, "no_such_scene.json")
    argv = [mpi, "--oversubscribe", "-np", "1"] + sensor_args(duplex, scene, 1000, 1, out) + \
           [":", "-np", "1"] + sensor_args(duplex, absent, 1000, 1, out)
    start = time.time()
    p = run(argv, timeout=60, check=False)
    expect(p.returncode != 0, "a rank without its scene: exit 0")
    expect(p.stderr.count("rank 1 of 2: " + absent) == 2,
           "every rank should name rank 1 and the missing file:\n" + p.stderr)
    expect(p.stdout == "", "a report was printed: " + p.stdout)
    expect(not os.path.exists(os.path.join(out, "run_state.bin")) and not os.path.exists(os.path.join(out, "run.json")),
           "files were written")
    print("a rank given a missing scene: every rank ends with the message, exit %d, nothing written (%.1f s): ok"
          % (p.returncode, time.time() - start))


def main(argv):
    if len(argv) != 6:
        print(__doc__)
        return 2
    what, duplex, mpi, with_mpi, d = argv[1:]
    if with_mpi.upper() not in ("ON", "1", "TRUE", "YES"):
        print("skipped: this build has no MPI (DUPLEX_WITH_MPI is OFF; Debian: libopenmpi-dev openmpi-bin)")
        return SKIP
    if not mpi or not shutil.which(mpi):
        print("skipped: no mpirun (Debian: openmpi-bin)")
        return SKIP
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    scene = os.path.join(d, "scene.json")
    with open(scene, "w") as f:
        json.dump(SCENE, f)
    checks = {"ranks": check_ranks, "target": check_target, "resume": check_resume, "kill": check_kill,
              "missing": check_missing}
    try:
        checks[what](duplex, mpi, d, scene)
    except Failure as e:
        print("FAILED: %s" % e)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
