#!/usr/bin/env python3
"""CTest check of the dynamic demo (duplex_demo on examples/scenes/car.json) at a tiny resolution.

Drives the demo as a user would and checks what it promises: exit 0; the before, after and
per-frame PNGs exist with the requested size (one frame before the edits plus one per distinct edit
time); the JSON summary holds the figures, consistent with the scene file; the edits change the
image; the right door's centre is picked as the door before the edits and, after the door opened,
as another part of the same car (the probe point moves with the car); and the final image does not
depend on the thread count.

Usage: demo_check.py DEMO SCENE WORK_DIR
"""

import json
import math
import os
import shutil
import struct
import subprocess
import sys
import zlib

WIDTH, HEIGHT = 96, 60
DOOR = "/car/door_right/door"


def fail(message):
    print("FAIL: " + message)
    sys.exit(1)


def expect(condition, message):
    if not condition:
        fail(message)


def read_png(path):
    """(width, height, rows of RGB bytes) of an 8-bit RGB, non-interlaced PNG."""
    with open(path, "rb") as f:
        return decode_png(f.read(), path)


def decode_png(data, path="the image"):
    """read_png of PNG bytes; `path` names them in messages."""
    expect(data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG")
    pos, idat, header = 8, b"", None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + length]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    expect(header is not None, f"{path}: no IHDR chunk")
    width, height, depth, colour, _, _, interlace = header
    expect(depth == 8 and colour == 2 and interlace == 0, f"{path}: not 8-bit RGB non-interlaced: {header}")
    raw, stride, rows, prev = zlib.decompress(idat), 3 * width, [], bytearray(3 * width)
    for y in range(height):
        filt, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - 3] if i >= 3 else 0
            b, c = prev[i], (prev[i - 3] if i >= 3 else 0)
            if filt == 1:
                line[i] = (line[i] + a) & 255
            elif filt == 2:
                line[i] = (line[i] + b) & 255
            elif filt == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif filt == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
            else:
                expect(filt == 0, f"{path}: unknown filter {filt}")
        rows.append(bytes(line))
        prev = line
    return width, height, rows


def changed_fraction(a, b):
    pixels = a[0] * a[1]
    changed = sum(1 for ra, rb in zip(a[2], b[2]) for x in range(a[0]) if ra[3 * x:3 * x + 3] != rb[3 * x:3 * x + 3])
    return changed / pixels


def check_images(out_dir, frame_count, width, height):
    """Checks before.png, after.png and frames/frame_NNN.png of a demo run writing to `out_dir`:
    sizes, one frame per `frame_count`, the first and last frames equal to before and after, and
    the edits changed the image. Returns (before, after, fraction of the pixels changed)."""
    before, after = read_png(os.path.join(out_dir, "before.png")), read_png(os.path.join(out_dir, "after.png"))
    for name, img in (("before", before), ("after", after)):
        expect(img[:2] == (width, height), f"{name}.png is {img[0]} x {img[1]}, expected {width} x {height}")
    frames = sorted(os.listdir(os.path.join(out_dir, "frames")))
    expect(frames == [f"frame_{k:03d}.png" for k in range(frame_count)], f"frames written: {frames}")
    expect(read_png(os.path.join(out_dir, "frames", frames[0])) == before, "frame_000.png differs from before.png")
    expect(read_png(os.path.join(out_dir, "frames", frames[-1])) == after, "the last frame differs from after.png")
    changed = changed_fraction(before, after)
    expect(changed > 0.02, f"the edits changed only {changed:.1%} of the pixels")
    return before, after, changed


def run_demo(demo, scene, out_dir, threads, frames, width=WIDTH, height=HEIGHT, probe=DOOR):
    """Runs the demo on `scene` into `out_dir`; returns its stdout and its JSON summary (the last line)."""
    args = [demo, "--scene", scene, "--width", str(width), "--height", str(height), "--threads", str(threads),
            "--before", os.path.join(out_dir, "before.png"), "--out", os.path.join(out_dir, "after.png"),
            "--probe", probe]
    if frames:
        args += ["--frames", os.path.join(out_dir, "frames")]
    r = subprocess.run(args, capture_output=True, text=True, timeout=120)
    expect(r.returncode == 0, f"{' '.join(args)} exited with {r.returncode}; stderr:\n{r.stderr}")
    lines = r.stdout.strip().splitlines()
    expect(lines, "the demo printed nothing")
    try:
        summary = json.loads(lines[-1])
    except json.JSONDecodeError as e:
        fail(f"the last line of the demo's output is not JSON ({e}):\n{r.stdout}")
    return r.stdout, summary


def main():
    if len(sys.argv) != 4:
        print(__doc__)
        return 2
    demo, scene_path, work = sys.argv[1:]
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    with open(scene_path) as f:
        scene = json.load(f)
    times = sorted({e["time"] for e in scene["edits"]})

    out, s = run_demo(demo, scene_path, os.path.join(work, "t2"), threads=2, frames=True)
    print(out)

    # The summary: figures present, finite, consistent with the scene file.
    for key in ("build_ms", "bottom_build_ms", "top_build_ms", "load_ms", "update_ms_median", "update_ms_max",
                "top_update_ms_median", "trace_ms_median", "mrays_per_s"):
        expect(isinstance(s.get(key), (int, float)) and math.isfinite(s[key]) and s[key] >= 0, f"summary key {key}: {s.get(key)}")
    expect(s["mrays_per_s"] > 0 and s["trace_ms_median"] > 0, "no trace figures")
    expect(math.isclose(s["build_ms"], s["bottom_build_ms"] + s["top_build_ms"], abs_tol=2e-4), "build_ms is not bottom + top")
    expect(s["format"] == "duplex-scene-v1", f"format {s['format']}")
    expect(s["objects"] == len(scene["objects"]), f"objects {s['objects']} != {len(scene['objects'])}")
    expect(s["edits"] == len(scene["edits"]), f"edits {s['edits']} != {len(scene['edits'])}")
    expect(s["commits"] == len(times), f"commits {s['commits']}: edits of equal time must form one commit ({len(times)} times)")
    expect(s["frames"] == len(times) + 1, f"frames {s['frames']} != {len(times) + 1}")
    expect(len(s["update_ms"]) == s["commits"] and all(ms > 0 for ms in s["update_ms"]), f"update_ms {s['update_ms']}")
    expect(s["width"] == WIDTH and s["height"] == HEIGHT, "size in the summary")
    expect(s["rays"] >= s["frames"] * WIDTH * HEIGHT, f"rays {s['rays']} < one primary ray per pixel and frame")

    # The PNGs: sizes, the frames, and the edits changed the image.
    _, after, changed = check_images(os.path.join(work, "t2"), s["frames"], WIDTH, HEIGHT)

    # Picking: the door's centre shows the door before; after the door opened (the point moved with
    # the car) it shows another part of the car, seen through the open door.
    (probe,) = s["probes"]
    expect(probe["node"] == DOOR, f"probe {probe}")
    expect(probe["hit_before"] == DOOR, f"before the edits, the door's centre picks {probe['hit_before']!r}, not the door")
    expect(probe["hit_after"].startswith("/car/") and not probe["hit_after"].startswith("/car/door_right"),
           f"after the door opened, its old centre picks {probe['hit_after']!r} (expected a part of /car behind the door)")
    expect(probe["pixel_before"] != probe["pixel_after"], "the probe point did not move with the car")

    # One thread renders the same final image.
    _, s1 = run_demo(demo, scene_path, os.path.join(work, "t1"), threads=1, frames=False)
    expect(read_png(os.path.join(work, "t1", "after.png")) == after, "the final image depends on the thread count")
    expect(s1["probes"] == s["probes"], f"the probe depends on the thread count: {s1['probes']} vs {s['probes']}")
    print(f"ok: {s['commits']} commits, {changed:.1%} of the pixels changed, probe {probe['hit_before']} -> {probe['hit_after']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
