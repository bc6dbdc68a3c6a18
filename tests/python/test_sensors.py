"""duplex.run_sensors against `duplex sensor`: the same arrays for the same seed; progress and cancel."""
import json

import numpy as np
import pytest

import duplex
from conftest import SCENES, run_cli

RAYS = 40000


@pytest.mark.parametrize("name,at", [("sensor_room.json", None), ("sensor_spectral.json", None),
                                     ("sensor_luminaire.json", 1), ("office_ies.json", None),
                                     ("light_guide.json", None)])
def test_run_equals_cli_output(cli, tmp_path, name, at):
    scene_file = SCENES / name
    at_args = ["--at", at] if at is not None else []
    report = run_cli(cli, "sensor", "--scene", scene_file, "--rays", RAYS, "--seed", 3, "--out", tmp_path,
                     "--progress", "none", "--threads", 2, *at_args)
    result = duplex.run_sensors(str(scene_file), rays=RAYS, seed=3, threads=1, at=at)
    assert sorted(result) == sorted(s["name"] for s in report["sensors"])
    for entry in report["sensors"]:
        ref = json.loads(open(entry["file"]).read())
        got = result[entry["name"]]
        nx, ny = ref["bins"]
        far = ref["shape"] == "farfield"
        assert got["bins"] == (nx, ny) and got["flux"].shape == ((nx, ny) if far else (ny, nx))
        # A scene whose lights are all in lumens (no wavelengths) transports lumens: the tool's "_w"
        # keys are null and its photometric keys hold what the module's unit-less entries hold.
        lumens = report["emitted_power_w"] is None
        keys = ((("intensity", "intensity_cd" if lumens else "intensity_w_sr"),
                 ("intensity_stderr", "intensity_stderr_cd" if lumens else "intensity_stderr_w_sr"),
                 ("solid_angle", "solid_angle_sr")) if far else
                (("irradiance", "illuminance_lx" if lumens else "irradiance_w_m2"),
                 ("stderr", "illuminance_stderr_lx" if lumens else "stderr_w_m2"), ("bin_area", "bin_area_m2")))
        for key, ref_key in keys + (("flux", "flux_lm" if lumens else "flux_w"), ("ray_count", "ray_count")):
            assert np.array_equal(got[key].ravel(), np.array(ref[ref_key])), key
        assert got["total_flux"] == ref["total_flux_lm" if lumens else "total_flux_w"]
        assert got["efficiency"] == ref["efficiency"]
        assert got["rays"] == RAYS and got["seed"] == 3 and got["status"] == "completed"
        assert got["emitted_power"] == report["emitted_flux_lm" if lumens else "emitted_power_w"]
        unit = "_lm" if lumens else "_w"
        assert got["energy"]["escaped_w"] == report["energy"]["escaped" + unit]
        assert got["energy"]["failed_w"] == report["energy"]["failed" + unit]
        for key in ("escaped_rays", "absorbed_rays", "depth_limited_rays", "roulette_rays", "failed_rays"):
            assert got["energy"][key] == report["energy"][key], key
        if "luminous_flux_lm" in ref:  # photometric scenes: the same luminous keys
            assert got["luminous_flux"] == ref["luminous_flux_lm"]
            assert got["emitted_luminous_flux"] == report["emitted_luminous_flux_lm"]
            lum = (("intensity_cd", "intensity_cd"), ("intensity_cd_stderr", "intensity_stderr_cd")) if far else \
                (("illuminance", "illuminance_lx"), ("illuminance_stderr", "illuminance_stderr_lx"))
            for key, ref_key in lum:
                assert np.array_equal(got[key].ravel(), np.array(ref[ref_key])), key
        else:
            assert "luminous_flux" not in got
        if "bands" in ref:
            assert got["bands"] == ref["bands"]
            assert np.array_equal(got["band_irradiance"].reshape(len(ref["bands"]), -1),
                                  np.array(ref["band_irradiance_w_m2"]))
        assert got["total_flux"] > 0


def test_progress_and_cancel():
    calls = []
    scene_file = str(SCENES / "sensor_room.json")
    duplex.run_sensors(scene_file, rays=200000, seed=1, progress=lambda done, total: calls.append((done, total)))
    assert len(calls) >= 3
    assert all(total == 200000 for _, total in calls)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls) and calls[-1][0] == 200000

    class Stop(Exception):
        pass

    seen = []

    def stop_after_two(done, total):
        seen.append(done)
        if len(seen) == 2:
            raise Stop("enough")

    with pytest.raises(Stop, match="enough"):
        duplex.run_sensors(scene_file, rays=10**8, seed=1, progress=stop_after_two)
    assert len(seen) == 2  # the run stopped at the batch after the exception


def test_bad_runs(tmp_path):
    with pytest.raises(OSError, match="missing.json"):
        duplex.run_sensors(str(tmp_path / "missing.json"), rays=10)
    with pytest.raises(ValueError, match="rays"):
        duplex.run_sensors(str(SCENES / "sensor_room.json"), rays=0)
    with pytest.raises(ValueError, match="failure_threshold"):
        duplex.run_sensors(str(SCENES / "sensor_room.json"), rays=10, failure_threshold=2)
    with pytest.raises(ValueError, match="progress"):
        duplex.run_sensors(str(SCENES / "sensor_room.json"), rays=10, progress=5)
    with pytest.raises(ValueError, match="target_sensor"):
        duplex.run_sensors(str(SCENES / "sensor_room.json"), rays=10, target_error=0.1, target_sensor="nobody")
    with pytest.raises(OSError, match="no sensors|no lights"):
        duplex.run_sensors(str(SCENES / "demo.json"), rays=10)


def test_target_error_stops_early():
    result = duplex.run_sensors(str(SCENES / "sensor_room.json"), rays=10**8, seed=2, target_error=0.05)
    first = next(iter(result.values()))
    assert first["status"] == "target_reached" and first["rays"] < 10**8


EDITED_SCENE = {
    "format": "duplex-scene-v1",
    "objects": [{"name": "plate", "sensor": {"size": [1, 1], "bins": [2, 2]}},
                {"name": "floor", "plane": {"size": 4}, "material": {"type": "lambertian", "reflectance": 0.5}}],
    "lights": [{"type": "point", "node": "/lamp", "position": [0, 0, 0], "power": 10}],
    "sensors": [{"name": "far", "shape": "farfield", "bins": [4, 3]}],
    "nodes": [{"instance": "floor", "object": "floor"},
              {"group": "rig", "translate": [0, 0, 1], "children": [{"instance": "plate", "object": "plate"}]},
              {"group": "lamp", "translate": [0, 0, 2]}],
    "edits": [{"time": 1, "node": "/rig/plate", "set_transform": {"translate": [0.3, 0, 0], "scale": 0.5}},
              {"time": 2, "node": "/lamp", "set_transform": {"translate": [0, 0, 3]}}],
}


def test_at_applies_the_timed_edits_as_the_cli_does(cli, tmp_path):
    """run_sensors(at=T) follows the edits up to T (sensor and light): the numbers of `duplex sensor --at T`."""
    scene_file = tmp_path / "edits.json"
    scene_file.write_text(json.dumps(EDITED_SCENE))
    report = run_cli(cli, "sensor", "--scene", scene_file, "--rays", 20000, "--seed", 3, "--out", tmp_path / "o",
                     "--progress", "none", "--threads", 1, "--at", 1.5)
    assert report["at"] == 1.5 and report["edits_applied"] == 1
    ref = json.loads((tmp_path / "o" / "plate.json").read_text())
    with pytest.warns(UserWarning, match="1 after at are not applied"):
        got = duplex.run_sensors(str(scene_file), rays=20000, seed=3, threads=2, at=1.5)
    assert got["plate"]["edits_applied"] == 1
    assert np.array_equal(got["plate"]["flux"].ravel(), np.array(ref["flux_w"]))
    assert np.array_equal(got["plate"]["bin_area"].ravel(), np.array(ref["bin_area_m2"]))
    assert np.allclose(got["plate"]["bin_area"], 0.0625)  # the scaled sensor's bins
    far = json.loads((tmp_path / "o" / "far.json").read_text())
    assert got["far"]["shape"] == "farfield" and got["far"]["intensity"].shape == (4, 3)
    assert np.array_equal(got["far"]["intensity"].ravel(), np.array(far["intensity_w_sr"]))
    assert list(got["far"]["gamma_deg"]) == far["gamma_deg"] == [0, 90, 180]
    with pytest.warns(UserWarning, match="2 timed edit.*not applied"):
        unedited = duplex.run_sensors(str(scene_file), rays=20000, seed=3, threads=1)
    assert unedited["plate"]["edits_applied"] == 0
    assert np.allclose(unedited["plate"]["bin_area"], 0.25)
    later = duplex.run_sensors(str(scene_file), rays=20000, seed=3, threads=1, at=5)
    assert later["plate"]["edits_applied"] == 2
    assert later["plate"]["total_flux"] < got["plate"]["total_flux"]  # the lamp moved up
    with pytest.raises(ValueError, match="at"):
        duplex.run_sensors(str(scene_file), rays=10, at=-1.0)


def test_colour_keys_of_bands_with_wavelengths(tmp_path):
    """Bands with wavelengths: CIE XYZ per bin whose Y is the illuminance, one band's chromaticity
    everywhere it is lit, NaN where no light arrived."""
    scene = {"format": "duplex-scene-v1",
             "objects": [{"name": "plate", "sensor": {"size": [4, 4], "bins": [6, 6], "two_sided": False}}],
             "nodes": [{"instance": "plate", "object": "plate"}],
             "bands": [{"name": "green", "nm": [540, 560]}, {"name": "red", "nm": [620, 640]}],
             "lights": [{"type": "spot", "position": [0, 0, 1], "direction": [0, 0, -1], "half_angle": 40,
                         "lumens": 100, "spectrum": [1, 0]}]}
    path = tmp_path / "colour.json"
    path.write_text(json.dumps(scene))
    got = duplex.run_sensors(str(path), rays=20000, seed=4)["plate"]
    assert got["cie_xyz"].shape == (6, 6, 3) and got["chromaticity_xy"].shape == (6, 6, 2)
    assert np.allclose(got["cie_xyz"][:, :, 1], got["illuminance"], rtol=1e-12, atol=0)
    lit = got["flux"] > 0
    assert lit.any() and (~lit).any()
    xy = got["chromaticity_xy"][lit]
    assert np.allclose(xy, xy[0], rtol=0, atol=1e-12) and 0.2 < xy[0][0] < 0.4 and xy[0][1] > 0.6
    assert np.isnan(got["chromaticity_xy"][~lit]).all()
    assert got["emitted_luminous_flux"] == pytest.approx(100.0, rel=1e-12)
    assert got["band_nm"] == [[540.0, 560.0], [620.0, 640.0]] or got["band_nm"] == [(540.0, 560.0), (620.0, 640.0)]


def test_lighting_meters_and_per_light_equal_the_cli(cli, tmp_path):
    """run_lighting's meters (an illuminance and a luminance meter under a sky with its sun) and
    run_sensors' per-light arrays hold the numbers of `duplex sensor --per-light` for the same seed,
    and the per-light values add up to the totals."""
    scene = tmp_path / "daylight.json"
    scene.write_text(json.dumps({
        "format": "scene-json-v1", "objects": [], "instances": [],
        "lights": [{"type": "sky", "name": "day", "model": "clear", "horizontal_illuminance": 10000,
                    "sun": {"altitude": 40, "azimuth": 150, "normal_illuminance": 50000},
                    "centre": [0, 0, 0], "radius": 2},
                   {"type": "point", "name": "lamp", "position": [0.3, 0, 1], "lumens": 2000}],
        "sensors": [{"name": "desk", "size": [1, 1], "bins": [2, 3], "two_sided": False}],
        "meters": [{"name": "desk_points", "points": [[0, 0, 0], [0.2, 0.1, 0]], "normal": [0, 0, 1]},
                   {"name": "eye", "points": [[0, 0, 0]], "normal": [0, 0, 1], "half_angle": 15},
                   {"name": "cam", "camera": {"eye": [0, 0, 0.1], "target": [1, 0, 1], "fov": 50,
                                              "pixels": [4, 3]}}]}))
    report = run_cli(cli, "sensor", "--scene", scene, "--rays", RAYS, "--seed", 5, "--out", tmp_path / "out",
                     "--progress", "none", "--threads", 2, "--per-light")
    got = duplex.run_lighting(str(scene), rays=RAYS, seed=5, threads=1, per_light=True)
    assert got["light_names"] == ["day", "day/sun", "lamp"] == [l["name"] for l in report["lights"]]
    assert got["rays"] == RAYS and got["status"] == "completed"
    by_name = {m["name"]: m for m in report["meters"]}
    points = got["meters"]["desk_points"]
    ref = by_name["desk_points"]
    assert points["points"].shape == (2, 3) and np.array_equal(points["points"], np.array(ref["points"]))
    assert np.array_equal(points["illuminance"], np.array(ref["illuminance_lx"]))
    assert np.array_equal(points["illuminance_stderr"], np.array(ref["illuminance_stderr_lx"]))
    assert np.array_equal(points["ray_count"], np.array(ref["ray_count"]))
    assert points["light_illuminance"].shape == (3, 2)
    for l, entry in enumerate(ref["lights"]):
        assert np.array_equal(points["light_illuminance"][l], np.array(entry["illuminance_lx"]))
    assert np.allclose(points["light_illuminance"].sum(axis=0), points["illuminance"], rtol=1e-12)
    eye, ref_eye = got["meters"]["eye"], by_name["eye"]
    assert "illuminance" not in eye and eye["half_angle_deg"] == pytest.approx(15.0, rel=1e-12)
    assert np.array_equal(eye["luminance"], np.array(ref_eye["luminance_cd_m2"]))
    assert np.array_equal(eye["light_luminance"][0], np.array(ref_eye["lights"][0]["luminance_cd_m2"]))
    cam, ref_cam = got["meters"]["cam"], by_name["cam"]
    assert cam["image_size"] == (4, 3) == tuple(ref_cam["image_size"]) and cam["luminance"].shape == (12,)
    assert np.array_equal(cam["luminance"], np.array(ref_cam["luminance_cd_m2"]))
    assert np.array_equal(cam["normals"], np.array(ref_cam["normals"]))
    # The sensors: the same as run_sensors, whose per-light arrays are the tool's.
    sensors = duplex.run_sensors(str(scene), rays=RAYS, seed=5, threads=1, per_light=True)
    desk = sensors["desk"]
    assert np.array_equal(desk["illuminance"], got["sensors"]["desk"]["illuminance"])
    ref_desk = json.loads(open(report["sensors"][0]["file"]).read())
    assert desk["light_names"] == ["day", "day/sun", "lamp"] and desk["light_illuminance"].shape == (3, 3, 2)
    for l, entry in enumerate(ref_desk["lights"]):
        assert np.array_equal(desk["light_illuminance"][l].ravel(), np.array(entry["illuminance_lx"]))
        assert desk["light_total_flux"][l] == entry["total_flux_lm"]
    assert np.allclose(desk["light_illuminance"].sum(axis=0), desk["illuminance"], rtol=1e-12)
    assert "light_names" not in duplex.run_sensors(str(scene), rays=1000, seed=5, threads=1)["desk"]
    # A scene of meters alone: run_lighting runs it, run_sensors refuses it.
    alone = tmp_path / "meters_only.json"
    data = json.loads(scene.read_text())
    del data["sensors"]
    alone.write_text(json.dumps(data))
    assert duplex.run_lighting(str(alone), rays=1000)["sensors"] == {}
    with pytest.raises(OSError, match="no sensors"):
        duplex.run_sensors(str(alone), rays=1000)
