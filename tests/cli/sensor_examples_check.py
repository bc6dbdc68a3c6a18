#!/usr/bin/env python3
"""The sensor examples that ship (examples/scenes): each runs `duplex sensor` in well under a second
and is checked against its expected figures: reference runs of 4,000,000 rays (seed 12345) with
their standard errors, combined with this run's, at 4.5 standard errors; and what optics says:
the office desk is lit at least by the luminaire's nadir candela over the squared distance, the
ball lens focuses at the paraxial n R / (2 (n - 1)) from its centre (the beam's RMS radius is
smallest there and the same 0.2 R before and after), the light guide's exit spreads its light.

usage: sensor_examples_check.py DUPLEX SCENES_DIR WORK_DIR
"""
import json
import math
import os
import shutil
import subprocess
import sys

RAYS = 200000
failures = []


def check(ok, what):
    if not ok:
        failures.append(what)
        print("FAIL:", what)


def near(value, se, expected, expected_se, what, k=4.5):
    combined = math.hypot(se, expected_se)
    check(abs(value - expected) <= k * combined,
          "%s: %.6g +- %.2g, expected %.6g +- %.2g" % (what, value, se, expected, expected_se))


def run(duplex, scenes, work, name):
    """Runs scenes/name.json into work/name; returns run.json and a reader of the sensors' JSON."""
    out = os.path.join(work, name)
    report = subprocess.run([duplex, "sensor", "--scene", os.path.join(scenes, name + ".json"), "--rays", str(RAYS),
                             "--seed", "1", "--threads", "2", "--out", out, "--overwrite", "--progress", "none"],
                            check=True, capture_output=True, text=True)
    check("warning" not in report.stderr, name + ": stderr warns: " + report.stderr)
    r = json.loads(report.stdout)
    check(r["energy"]["failed_rays"] == 0, name + ": numerical failures " + str(r["energy"]))
    return r, lambda sensor: json.load(open(os.path.join(out, sensor + ".json")))


def rms_radius(s):
    """The flux-weighted RMS distance of a square sensor's bins from its centre."""
    nx, ny = s["bins"]
    w, h = s["size"]
    total = sum(s["flux_w"])
    acc = 0.0
    for b, f in enumerate(s["flux_w"]):
        x = -w / 2 + (b % nx + 0.5) * w / nx
        y = -h / 2 + (b // nx + 0.5) * h / ny
        acc += f * (x * x + y * y)
    return math.sqrt(acc / total)


def main():
    duplex, scenes, work = sys.argv[1:4]
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)

    # Office: an IES downlight (its candela table, 3027 lm) 1.895 m above a desk sensor in lux.
    r, sensor = run(duplex, scenes, work, "office_ies")
    check(abs(r["emitted_luminous_flux_lm"] - 3027.1548) < 1e-3, "office: the luminaire emits its table's integral")
    desk = sensor("desk_lux")
    for key in ("luminous_flux_lm", "luminous_flux_stderr_lm", "illuminance_lx", "illuminance_stderr_lx"):
        check(key in desk, "office: desk_lux.json lacks " + key)
    area = desk["size"][0] * desk["size"][1]
    near(desk["luminous_flux_lm"] / area, desk["luminous_flux_stderr_lm"] / area, 299.842, 0.551, "office: mean desk lux")
    check(min(desk["illuminance_lx"]) > 920.0 / 1.895 ** 2 * 0.8,
          "office: the desk's darkest bin is below 80% of the nadir's direct light")
    check(r["energy"]["escaped_rays"] == 0, "office: light left a closed room")

    # Ball lens: radius 1, n 1.5, a collimated beam of radius 0.1 (faceted icosphere, 81,920 triangles).
    r, sensor = run(duplex, scenes, work, "ball_lens")
    focus, before, after = sensor("focus"), sensor("near"), sensor("far")
    near(focus["total_flux_w"], focus["total_flux_stderr_w"], 0.9217665, 0.000134, "ball lens: transmitted power")
    rf, rb, ra = rms_radius(focus), rms_radius(before), rms_radius(after)
    check(rf < 0.5 * rb and rf < 0.5 * ra, "ball lens: no focus at 1.5 R (RMS %.4g, %.4g before, %.4g after)" % (rf, rb, ra))
    check(abs(rb - ra) < 0.05 * rb, "ball lens: the focus is not midway (RMS %.4g before, %.4g after)" % (rb, ra))
    check(abs(rf - 0.004868) < 0.05 * 0.004868, "ball lens: RMS spot %.4g at the focus, expected 0.00487" % rf)
    check(max(focus["irradiance_w_m2"]) > 100.0 / (math.pi * 0.1 ** 2), "ball lens: concentration below 100")

    # Light guide: PMMA rod with a rough exit face, an LED at its entrance.
    r, sensor = run(duplex, scenes, work, "light_guide")
    screen, far = sensor("screen"), sensor("exit_far_field")
    near(screen["total_flux_w"], screen["total_flux_stderr_w"], 0.5978194, 0.000211, "light guide: screen flux")
    near(far["intensity_w_sr"][0], far["intensity_stderr_w_sr"][0], 0.263016, 0.00446, "light guide: on-axis W/sr")
    check(abs(r["energy"]["absorbed_w"] - 0.10512) < 0.004, "light guide: absorbed %.4g W, expected 0.105 (PMMA)"
          % r["energy"]["absorbed_w"])
    # The rough face spreads the light: the axial intensity falls off gradually, not a specular beam.
    gamma = far["gamma_deg"]
    ng = len(gamma)
    mean = [sum(far["intensity_w_sr"][c * ng + g] for c in range(far["bins"][0])) / far["bins"][0] for g in range(ng)]
    check(mean[3] > 0.7 * mean[0] and mean[6] < 0.6 * mean[0], "light guide: exit profile %s" % mean[:8])

    # Photometric far field: an isotropic 1000 lm source measured in candela, its .ies in candela.
    scene = {"format": "scene-json-v1", "objects": [], "instances": [],
             "lights": [{"type": "point", "position": [0, 0, 0], "lumens": 1000}],
             "sensors": [{"name": "far", "shape": "farfield", "bins": [4, 5]}]}
    with open(os.path.join(work, "lumens.json"), "w") as f:
        json.dump(scene, f)
    r, sensor = run(duplex, work, work, "lumens")
    far = sensor("far")
    check(r["emitted_luminous_flux_lm"] == 1000, "lumens: emitted_luminous_flux_lm %s" % r["emitted_luminous_flux_lm"])
    check(abs(far["luminous_flux_lm"] - 1000) < 1e-9, "lumens: the far field's luminous flux is not 1000 lm")
    for c, (i, se) in enumerate(zip(far["intensity_cd"], far["intensity_stderr_cd"])):
        check(abs(i - 1000 / (4 * math.pi)) < 4.5 * se, "lumens: cell %d: %.5g cd, expected %.5g" % (c, i, 1000 / (4 * math.pi)))
    ies = open(os.path.join(work, "lumens", "far.ies")).read()
    check("[_UNITS] cd" in ies and "candela" in ies, "lumens: far.ies is not in candela")

    if failures:
        print("%d failure(s)" % len(failures))
        return 1
    print("sensor examples: all figures as expected")
    return 0


if __name__ == "__main__":
    sys.exit(main())
