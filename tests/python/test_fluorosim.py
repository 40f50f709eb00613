"""`import fluorosim` (python/fluorosim_module.cpp) against the CLI: the same numbers for the same
options, the same error messages, a stack round trip through tifffile with its metadata, the GIL
released while rendering, and docs/python.md's examples run as written. Run by ctest (tests/CMakeLists.txt) with PYTHONPATH at build/python."""
import copy
import json
import os
import shutil
import subprocess
import sys
import threading
import time
import types
from pathlib import Path

import numpy as np
import pytest
import tifffile

import fluorosim

CLI = os.environ["FLUOROSIM_CLI"]
SOURCE = Path(os.environ["FLUOROSIM_SOURCE_DIR"])
BEADS = SOURCE / "samples" / "lightsheet" / "beads.json"

# A small render scene (the CLI tests' floor, ball and light).
SMALL = {
    "fluorosim_scene": 1,
    "spectral": {"range": ["400 nm", "700 nm"], "bin_width": "50 nm"},
    "render": {"seed": 1, "spp": 4},
    "camera": {"position": ["0 mm", "50 mm", "-200 mm"], "look_at": ["0 mm", "50 mm", "0 mm"], "fov_y_deg": 40,
               "resolution": [24, 16]},
    "materials": {"white": {"type": "diffuse", "reflectance": 0.7}},
    "shapes": [
        {"type": "quad", "name": "floor", "origin": ["-100 mm", "0 mm", "-100 mm"], "edge1": ["200 mm", "0 mm", "0 mm"],
         "edge2": ["0 mm", "0 mm", "200 mm"], "material": "white"},
        {"type": "sphere", "name": "ball", "center": ["0 mm", "30 mm", "0 mm"], "radius": "30 mm", "material": "white"},
        {"type": "quad", "name": "light", "origin": ["-20 mm", "120 mm", "-20 mm"], "edge1": ["40 mm", "0 mm", "0 mm"],
         "edge2": ["0 mm", "0 mm", "40 mm"], "emission": {"radiance": {"reference": "illuminant:D65", "scale": 0.1}, "two_sided": True}},
    ],
}


def beads(width=16):
    scene = json.loads(BEADS.read_text())
    scene["shapes"][0]["file"] = str(BEADS.parent / "bath.obj")
    scene["microscope"]["detector"]["width"] = width
    scene["microscope"]["detector"]["height"] = width
    return scene


def cli(*args):
    return subprocess.run([CLI, *map(str, args)], capture_output=True, text=True, timeout=300)


def test_acquire_gives_the_cli_stack(tmp_path):
    scene = tmp_path / "beads.json"
    scene.write_text(json.dumps(beads()))
    options = ["--planes", "4", "--spp", "4", "--seed", "3", "--step", "1um"]
    run = cli("acquire", scene, "-o", tmp_path / "s.ome.tif", *options)
    assert run.returncode == 0, run.stderr
    stack = fluorosim.acquire(str(scene), planes=4, spp=4, seed=3, step="1um")
    assert stack["counts"].shape == (1, 4, 16, 16) and stack["counts"].dtype == np.uint16
    assert stack["channels"] == ["AF488"]
    assert stack["pixel_size_um"] == pytest.approx(6.5 / 16, rel=1e-12)
    assert stack["z_step_um"] == pytest.approx(1.0, rel=1e-12)
    counts = tifffile.imread(tmp_path / "s.ome.tif")
    expected = tifffile.imread(tmp_path / "s.expected.ome.tif")
    np.testing.assert_array_equal(stack["counts"].ravel(), counts.ravel())
    np.testing.assert_array_equal(stack["expected"].ravel(), expected.ravel())
    assert stack["expected"].max() > stack["expected"].min()
    # The CLI's summary, under the same names; timings and file paths aside, the same numbers.
    summary = json.loads(run.stdout)
    for key in ("planes", "channels", "width", "spp", "seed", "estimator", "computed_electrons_fraction", "computed_points", "paths",
                "largest_sample_electrons", "max_expected_electrons", "saturated_pixels", "saturated_monte_carlo_pixels",
                "saturated_borderline_pixels", "exposure_s", "exposure_auto", "noise_ratio_target"):
        assert stack["summary"][key] == summary[key], key
    assert set(summary["computed_timings"]) == set(stack["summary"]["computed_timings"])
    # The same scene as a dict (relative mesh path resolved against `base`).
    scene_dict = beads()
    scene_dict["shapes"][0]["file"] = "bath.obj"
    from_dict = fluorosim.acquire(scene_dict, planes=4, spp=4, seed=3, step="1um", base=str(BEADS.parent))
    np.testing.assert_array_equal(from_dict["counts"], stack["counts"])


def test_acquire_sets_the_exposure_as_the_cli_does(tmp_path):
    scene = tmp_path / "beads.json"
    scene.write_text(json.dumps(beads()))
    run = cli("acquire", scene, "-o", tmp_path / "s.ome.tif", "--planes", "2", "--spp", "2", "--exposure", "auto:0.4")
    assert run.returncode == 0, run.stderr
    stack = fluorosim.acquire(str(scene), planes=2, spp=2, exposure="auto:0.4")
    summary = json.loads(run.stdout)
    assert stack["exposure_s"] == summary["exposure_s"] == stack["summary"]["exposure_s"]
    assert stack["summary"]["exposure_auto"] == summary["exposure_auto"]
    np.testing.assert_array_equal(stack["counts"].ravel(), tifffile.imread(tmp_path / "s.ome.tif").ravel())
    with pytest.raises(ValueError, match="--exposure"):
        fluorosim.acquire(str(scene), planes=1, spp=1, exposure="auto:2")


def test_acquire_reads_the_cameras_calibration_maps(tmp_path):
    # An sCMOS offset map (100 + column) and gain map as TIFF files, as cameras ship their calibration.
    offset = np.tile(100.0 + np.arange(16, dtype=np.float32), (16, 1)).astype(np.float32)
    gain = np.full((16, 16), 0.5, dtype=np.float32)
    tifffile.imwrite(tmp_path / "offset.tif", offset)
    tifffile.imwrite(tmp_path / "gain.tif", gain)
    scene = beads()
    scene["microscope"]["detector"].update(offset_map=str(tmp_path / "offset.tif"), gain_map=str(tmp_path / "gain.tif"),
                                           hot_pixel_fraction=0.05, hot_pixel_dark_e_per_s=5000)
    stack = fluorosim.acquire(scene, planes=1, spp=1, seed=2)
    counts, expected = stack["counts"][0, 0].astype(float), stack["expected"][0, 0]
    residual = counts - expected / 0.5 - offset  # shot and read noise: mean 0, per pixel sqrt(e + 1.4^2) / 0.5 ADU
    assert abs(residual.mean()) < 4 * np.sqrt(((expected + 1.4 ** 2) / 0.25 + 1 / 12).sum()) / residual.size
    hot = expected > 5000 * 0.01 * 0.5  # the hot pixels' dark electrons (5000 e-/s over the 10 ms exposure)
    assert 0 < hot.sum() < 40
    scene["microscope"]["detector"]["gain_map"] = str(tmp_path / "small.tif")
    tifffile.imwrite(tmp_path / "small.tif", gain[:8])
    with pytest.raises(ValueError, match="gain_map.*16 x 8 pixels"):
        fluorosim.acquire(scene, planes=1, spp=1)


def test_acquire_takes_the_cli_estimator_options(tmp_path):
    scene = tmp_path / "beads.json"
    scene.write_text(json.dumps(beads()))
    options = ["--planes", "2", "--spp", "4", "--seed", "5", "--estimator", "path"]
    run = cli("acquire", scene, "-o", tmp_path / "p.ome.tif", *options)
    assert run.returncode == 0, run.stderr
    stack = fluorosim.acquire(str(scene), planes=2, spp=4, seed=5, estimator="path")
    assert stack["estimator"] == "path"
    np.testing.assert_array_equal(stack["expected"].ravel(), tifffile.imread(tmp_path / "p.expected.ome.tif").ravel())
    options = ["--planes", "1", "--spp", "4", "--seed", "5", "--noise-ratio", "0.5", "--max-spp", "64"]
    run = cli("acquire", scene, "-o", tmp_path / "a.ome.tif", *options)
    assert run.returncode == 0, run.stderr
    adaptive = fluorosim.acquire(str(scene), planes=1, spp=4, seed=5, noise_ratio=0.5, max_spp=64)
    np.testing.assert_array_equal(adaptive["expected"].ravel(), tifffile.imread(tmp_path / "a.expected.ome.tif").ravel())
    with pytest.raises(ValueError, match="--estimator"):
        fluorosim.acquire(str(scene), planes=1, estimator="fast")
    with pytest.raises(ValueError, match="--noise-ratio: must be positive"):
        fluorosim.acquire(str(scene), planes=1, noise_ratio=-1.0)
    with pytest.raises(ValueError, match="--threads"):
        fluorosim.acquire(str(scene), planes=1, threads=65537)
    # The sampled direct part is gone: its option says so instead of being ignored.
    with pytest.raises(ValueError, match="direct_spp: removed"):
        fluorosim.acquire(str(scene), planes=1, direct_spp=32)


def test_voxelize_writes_the_cli_grids(tmp_path):
    swc = [str(SOURCE / "samples" / "neurons" / "C231296A-P3.CNG.swc")]
    run = cli("voxelize", *swc, "--voxel", "1um", "--dye", "AF594", "--concentration", "10uM", "-o", tmp_path / "cli.vdb")
    assert run.returncode == 0, run.stderr
    s = fluorosim.voxelize(swc, voxel="1um", dyes=["AF594"], concentrations=["10uM"], output=str(tmp_path / "py.vdb"))
    (grid,) = s["grids"]
    # The files differ only in OpenVDB's per-file UUID; the CLI's summary line gives the same grid.
    assert f"grid alexa_fluor_594 [uM]: {grid['active_voxels']} voxels, covered {grid['covered_volume_um3']:.6g} um^3" in run.stdout
    assert (tmp_path / "cli.vdb").stat().st_size == (tmp_path / "py.vdb").stat().st_size
    # pathlib.Path wherever a path is meant.
    fluorosim.voxelize([Path(swc[0])], voxel="1um", dyes=["AF594"], concentrations=["10uM"], output=tmp_path / "path.vdb")
    assert (tmp_path / "path.vdb").stat().st_size == (tmp_path / "py.vdb").stat().st_size
    assert grid["name"] == "alexa_fluor_594" and grid["units"] == "uM" and grid["max_value"] == pytest.approx(10, rel=1e-6)
    assert grid["covered_volume_um3"] == pytest.approx(grid["analytic_volume_um3"], rel=0.05)
    with pytest.raises(ValueError, match="--voxel"):
        fluorosim.voxelize(swc, voxel="-1um", dyes=["AF594"], concentrations=["10uM"], output=str(tmp_path / "x.vdb"))
    # Two copies of the neuron in one grid: overlapping they add up; placed apart they do not.
    two = dict(voxel="1um", dyes=["AF594"], concentrations=["10uM"], grids=["cells"])
    (together,) = fluorosim.voxelize(swc * 2, output=tmp_path / "t.vdb", **two)["grids"]
    (apart,) = fluorosim.voxelize(swc * 2, output=tmp_path / "a.vdb", offsets=["0um,0um,0um", "3mm,0um,0um"], rotations=["z:90"], **two)["grids"]
    assert together["max_value"] == pytest.approx(20, rel=1e-6) and apart["max_value"] == pytest.approx(10, rel=1e-6)


def test_the_spectral_database_as_arrays():
    assert "alexa_fluor_488" in fluorosim.dyes() and "semrock_FF01-525-45" in fluorosim.filters()
    wl = np.arange(400.0, 751.0, 1.0)
    af488 = fluorosim.dye("AF488", wl)  # an alias of alexa_fluor_488
    assert af488["molar_extinction"].shape == wl.shape
    assert af488["molar_extinction"].max() == pytest.approx(af488["extinction_peak"], rel=0.02)
    assert np.trapz(af488["emission_pdf"], wl) == pytest.approx(1.0, abs=0.01)  # a density over the range it covers
    assert 480 < wl[np.argmax(af488["molar_extinction"])] < 510 and 505 < wl[np.argmax(af488["emission_pdf"])] < 535
    t = fluorosim.filter_transmission("semrock_FF01-525-45", wl)
    assert t[wl == 525][0] > 0.9 and t[wl == 450][0] < 1e-3
    with pytest.raises(ValueError):
        fluorosim.dye("no such dye", wl)
    with pytest.raises(ValueError, match="wavelengths_nm"):
        fluorosim.filter_transmission("semrock_FF01-525-45", [500.0, -1.0])


def test_render_from_a_dict_matches_the_file_and_has_its_wavelengths(tmp_path):
    path = tmp_path / "small.json"
    path.write_text(json.dumps(SMALL))
    a = fluorosim.render(SMALL, seed=5)
    b = fluorosim.render(str(path), seed=5, threads=1)
    assert a["rgb"].shape == (16, 24, 3)
    np.testing.assert_array_equal(a["rgb"], b["rgb"])
    np.testing.assert_array_equal(a["wavelengths_nm"], [425, 475, 525, 575, 625, 675])
    assert a["spectral"]["total"].shape == (6, 16, 24)
    assert a["spp"] == 4 and a["paths"] == 4 * 16 * 24
    assert a["rgb"].mean() > 0
    other = fluorosim.render(SMALL, seed=6)
    assert not np.array_equal(a["rgb"], other["rgb"])


def test_errors_carry_the_cli_messages(tmp_path):
    path = tmp_path / "small.json"
    path.write_text(json.dumps(SMALL))
    run = cli("render", path, "-o", tmp_path / "x.exr", "--spp", "0")
    assert run.returncode == 2
    with pytest.raises(ValueError) as e:
        fluorosim.render(str(path), spp=0)
    assert run.stderr == f"fluorosim: error: {e.value}\n"
    missing = tmp_path / "missing.json"
    run = cli("render", missing, "-o", tmp_path / "x.exr")
    assert run.returncode == 3
    with pytest.raises(OSError) as e:
        fluorosim.render(str(missing))
    assert run.stderr == f"fluorosim: I/O error: {e.value}\n"
    bad = copy.deepcopy(SMALL)
    bad["camera"]["fov_y_deg"] = "wide"
    with pytest.raises(ValueError, match="fov_y_deg"):
        fluorosim.render(bad)
    with pytest.raises(ValueError, match='--channels: .*"mCherry"'):
        fluorosim.acquire(beads(), channels=["mCherry"], planes=1, spp=1)


def test_stack_round_trips_through_tifffile_with_its_metadata(tmp_path):
    scene = beads()
    second = copy.deepcopy(scene["microscope"]["channels"][0])
    second["name"] = "AF488b"
    scene["microscope"]["channels"].append(second)
    stack = fluorosim.acquire(scene, planes=2, spp=2, seed=1)
    assert stack["expected"].shape == (2, 2, 16, 16) and stack["channels"] == ["AF488", "AF488b"]
    out = tmp_path / "stack.ome.tif"
    tifffile.imwrite(out, stack["expected"], ome=True,
                     metadata={"axes": "CZYX", "PhysicalSizeX": stack["pixel_size_um"], "PhysicalSizeY": stack["pixel_size_um"],
                               "PhysicalSizeZ": stack["z_step_um"], "Channel": {"Name": stack["channels"]}})
    with tifffile.TiffFile(out) as tif:
        back = tif.series[0].asarray()
        assert tif.series[0].axes == "CZYX"
        pixels = tifffile.xml2dict(tif.ome_metadata)["OME"]["Image"]["Pixels"]
    np.testing.assert_array_equal(back, stack["expected"])
    assert pixels["PhysicalSizeX"] == pytest.approx(stack["pixel_size_um"])
    assert pixels["PhysicalSizeZ"] == pytest.approx(stack["z_step_um"])
    assert [c["Name"] for c in pixels["Channel"]] == stack["channels"]


def test_the_gil_is_released_while_rendering():
    scene = copy.deepcopy(SMALL)
    scene["camera"]["resolution"] = [96, 64]
    done = threading.Event()
    seconds = []

    def work():
        seconds.append(fluorosim.render(scene, spp=64, threads=1)["seconds"])
        done.set()

    thread = threading.Thread(target=work)
    thread.start()
    ticks = 0
    while not done.is_set():  # runs only while the render thread does not hold the GIL
        ticks += 1
        time.sleep(0.001)
    thread.join()
    # With the GIL held for the whole render this loop would run once or twice.
    assert seconds[0] > 0.05, "the render was too short to tell"
    assert ticks > 10, f"{ticks} ticks during a {seconds[0]:.2f} s render"


def test_fit_gives_the_cli_numbers_from_a_file_and_from_an_array(tmp_path):
    # The beads as one parameter (a homogeneous dyed medium: --unlabelled), fitted back from their own stack.
    scene = tmp_path / "beads.json"
    scene.write_text(json.dumps(beads()))
    stack = tmp_path / "s.ome.tif"
    run = cli("acquire", scene, "-o", stack, "--planes", "4", "--spp", "4", "--seed", "3", "--step", "1um")
    assert run.returncode == 0, run.stderr
    run = cli("fit", scene, "--stack", stack, "--planes", "4", "--step", "1um", "--unlabelled", "-o", tmp_path / "fit")
    assert run.returncode == 0, run.stderr
    cli_fit = json.loads((tmp_path / "fit" / "fit.json").read_text())
    for name in ["model.ome.tif", "residual.ome.tif", "normalised_residual.ome.tif", "fit.log", "solver_report.txt"]:
        assert (tmp_path / "fit" / name).exists(), name
    assert [p["medium"] for p in cli_fit["parameters"]] == ["bead"]
    from_file = fluorosim.fit(str(scene), stack, planes=4, step="1um", unlabelled=True)
    assert from_file["theta"][0] == pytest.approx(cli_fit["parameters"][0]["theta"], rel=1e-12)
    assert from_file["standard_error"][0] == pytest.approx(cli_fit["parameters"][0]["standard_error"], rel=1e-9)
    # The stack's own metadata, read by tifffile, and its pixels as an array: the same fit.
    with tifffile.TiffFile(stack) as f:
        counts = f.asarray().reshape(1, 4, 16, 16)
    camera = {"sensor": "sCMOS", "gain_e_per_adu": 0.46, "offset_adu": 100, "read_noise_e": 1.4}
    from_array = fluorosim.fit(str(scene), counts, planes=4, step="1um", unlabelled=True, stack_channels=["AF488"],
                               pixel_size_um=0.40625, z_step_um=1.0, camera=camera)
    assert from_array["theta"][0] == pytest.approx(from_file["theta"][0], rel=1e-12)
    assert from_array["model"].shape == (1, 4, 16, 16)
    # The beads were acquired at the scene's concentration: the fit finds it within its own error and
    # the camera's noise (the scattered light of clear water is nil).
    assert abs(from_file["theta"][0] - 1) < 4 * from_file["standard_error"][0] + 0.01


def test_fit_and_gradient_refuse_bad_input_with_the_cli_messages(tmp_path):
    scene = tmp_path / "beads.json"
    scene.write_text(json.dumps(beads()))
    stack = tmp_path / "s.ome.tif"
    assert cli("acquire", scene, "-o", stack, "--planes", "2", "--spp", "1", "--step", "1um").returncode == 0
    # The stack has 2 planes; the scene's microscope another count.
    run = cli("fit", scene, "--stack", stack, "--unlabelled", "-o", tmp_path / "fit")
    assert run.returncode == 2 and "SizeZ" in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr
    with pytest.raises(ValueError, match="SizeZ"):
        fluorosim.fit(str(scene), stack, unlabelled=True)
    with pytest.raises(ValueError, match="params"):
        fluorosim.fit(str(scene), stack, planes=2, step="1um", params="voxels")
    with pytest.raises(ValueError, match="label_grid"):
        fluorosim.fit(str(scene), stack, planes=2, step="1um")
    with pytest.raises(ValueError, match="stack"):
        fluorosim.fit(str(scene), np.zeros((2, 2)))
    plain = tmp_path / "plain.tif"
    tifffile.imwrite(plain, np.zeros((2, 16, 16), np.uint16))
    with pytest.raises(ValueError, match="not an OME-TIFF"):
        fluorosim.fit(str(scene), plain, planes=2, step="1um", unlabelled=True)
    run = cli("fit", scene, "--stack", plain, "--planes", "2", "--step", "1um", "--unlabelled", "-o", tmp_path / "fit2")
    assert run.returncode == 2 and "not an OME-TIFF" in run.stderr, run.stderr


def test_gradient_columns_match_the_cli(tmp_path):
    scene = tmp_path / "beads.json"
    scene.write_text(json.dumps(beads()))
    out = tmp_path / "g.ome.tif"
    run = cli("gradient", scene, "--params", "grid:4um", "-o", out)
    assert run.returncode == 0, run.stderr
    index = json.loads((tmp_path / "g.json").read_text())
    g = fluorosim.gradient(str(scene), params="grid:4um")
    assert g["columns"].shape[0] == len(index["parameters"]) == len(g["parameters"])
    with tifffile.TiffFile(out) as f:
        cli_columns = f.asarray().reshape(g["columns"].shape)
    np.testing.assert_array_equal(cli_columns, g["columns"])
    assert (g["columns"] >= -1e-6 * g["columns"].max()).all()


def test_ground_truth_beside_the_acquired_stack():
    """The perfect microscope's image and the concentration on the stack's grid, with the geometry that
    places each pixel in the scene: a bead put at a pixel centre is found there, and the perfect image is
    brightest on it; the acquired stack (through 200 um of water) is no brighter than the perfect one."""
    scene = beads(width=32)
    bead = copy.deepcopy(scene["shapes"][1])
    pixel = 6.5 / 16
    x, y = 20, 9  # column and row of the bead
    centre = [(x + 0.5 - 16) * pixel, (16 - y - 0.5) * pixel, 0.0]
    bead["center"] = [f"{c} um" for c in centre]
    bead["radius"] = "0.15 um"
    scene["shapes"] = [scene["shapes"][0], bead]
    truth = fluorosim.ground_truth(scene, planes=3, step="1um")
    assert truth["axes"] == "CZYX"
    assert truth["ideal"].shape == (1, 3, 32, 32)
    assert list(truth["concentration"]) == ["alexa_fluor_488"]
    c = truth["concentration"]["alexa_fluor_488"]
    assert c.shape == (3, 32, 32)
    assert c[1, y, x] == pytest.approx(1e-3, rel=1e-6)  # the bead's 1 mM, in mol/L, at its pixel of the middle plane
    assert np.count_nonzero(c) == 1
    origin = np.array(truth["origin_um"])
    found = origin + x * np.array(truth["x_step_um"]) + y * np.array(truth["y_step_um"]) + 1 * np.array(truth["z_step_vector_um"])
    np.testing.assert_allclose(found, centre, atol=1e-9)
    ideal = truth["ideal"][0, 1]
    assert np.unravel_index(np.argmax(ideal), ideal.shape) == (y, x)
    stack = fluorosim.acquire(scene, planes=3, step="1um", spp=4)
    assert stack["origin_um"] == truth["origin_um"]
    dark = 0.5 * 0.01
    assert (stack["expected"][0, 1] - dark).sum() <= ideal.sum() * 1.001


def test_library_warnings_reach_python():
    scene = beads()
    scene["microscope"]["detector"]["exposure_s"] = 20
    scene["lights"][0]["power_mW"] = "1 nW"
    with pytest.warns(UserWarning, match="exposure 20 s is long for one plane"):
        fluorosim.acquire(scene, planes=1, spp=1)


def test_numpy_concentrations_in_ground_truth_out(tmp_path):
    """A NumPy concentration array becomes a scene's volume without writing OpenVDB by hand, and the
    ground truth reads it back at the pixel centres: voxels the size of a pixel, centred on them."""
    rng = np.random.default_rng(4)
    c = rng.uniform(0, 20, size=(5, 16, 16))  # uM, (z, y, x)
    pixel = 6.5 / 16
    # array[k, j, i] at origin + (i, j, k) voxels; pixel (x, y) of plane 0 at ((x + 0.5 - 8) p, (8 - y - 0.5) p, 0):
    # rows run down the image, so the array's y axis is flipped.
    origin = [f"{(0.5 - 8) * pixel} um", f"{(0.5 - 8) * pixel} um", f"{-2 * pixel} um"]
    written = fluorosim.write_volume(tmp_path / "v.vdb", {"AF488": c}, voxel=f"{pixel} um", origin=origin, units="uM")
    assert written["grids"] == ["AF488"]
    scene = beads()
    scene["shapes"] = [scene["shapes"][0]]
    scene["media"]["water"]["dyes"] = [{"dye": "AF488", "grid": "AF488"}]
    scene["media"]["water"]["volume"] = {"file": str(tmp_path / "v.vdb"), "interpolation": "trilinear"}
    truth = fluorosim.ground_truth(scene, planes=1)
    got = truth["concentration"]["alexa_fluor_488"][0]
    np.testing.assert_allclose(got, c[2, ::-1, :] * 1e-6, rtol=1e-5)
    assert truth["ideal"][0, 0].max() > 0
    with pytest.raises(ValueError, match="values must be finite and >= 0"):
        fluorosim.write_volume(str(tmp_path / "bad.vdb"), {"AF488": -c}, voxel="1 um")


def test_acquire_reports_progress_and_stops_on_ctrl_c():
    import _thread

    seen = []
    fluorosim.acquire(beads(), planes=4, spp=2, progress=seen.append)
    assert seen and seen[-1] == 1.0
    assert all(0 <= a <= b <= 1 for a, b in zip(seen, seen[1:]))
    # Ctrl-C half a second into a run that takes far longer: KeyboardInterrupt within a few seconds.
    long_run = beads(width=256)
    timer = threading.Timer(0.5, _thread.interrupt_main)
    start = time.monotonic()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        fluorosim.acquire(long_run, planes=64, spp=64)
    assert time.monotonic() - start < 10


def test_render_reports_progress_and_stops_on_ctrl_c():
    import _thread

    seen = []
    fluorosim.render(SMALL, spp=8, progress=seen.append)
    assert seen and seen[-1] == 1.0
    assert all(0 <= a <= b <= 1 for a, b in zip(seen, seen[1:]))
    long_render = copy.deepcopy(SMALL)
    long_render["camera"]["resolution"] = [256, 256]
    timer = threading.Timer(0.5, _thread.interrupt_main)
    start = time.monotonic()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        fluorosim.render(long_render, spp=100000)
    assert time.monotonic() - start < 10


def docs_block(marker):
    """The Python block after an HTML comment marker in docs/python.md, as the reader sees it."""
    text = (SOURCE / "docs" / "python.md").read_text()
    after = text[text.index(marker):]
    start = after.index("```python\n") + len("```python\n")
    return after[start:after.index("```", start)]


def test_the_docs_napari_example_puts_channels_on_layers_at_their_physical_size(tmp_path, monkeypatch):
    calls = []

    class Viewer:
        def add_image(self, data, **kwargs):
            calls.append((data, kwargs))

    monkeypatch.setitem(sys.modules, "napari", types.SimpleNamespace(Viewer=Viewer))
    monkeypatch.chdir(SOURCE)
    namespace = {}
    exec(docs_block("<!-- napari-example"), namespace)
    (data, kwargs), = calls
    stack = namespace["stack"]
    assert data.shape == (1, 8, 64, 64) and kwargs["channel_axis"] == 0 and kwargs["name"] == ["AF488"]
    assert kwargs["scale"] == pytest.approx((1.0, 6.5 / 16, 6.5 / 16))
    # The CLI's file opens the same way: (C, Z, Y, X) and the same physical sizes in its OME metadata.
    run = cli("acquire", SOURCE / "samples" / "lightsheet" / "beads.json", "-o", tmp_path / "b.ome.tif", "--planes", "8", "--spp", "4")
    assert run.returncode == 0, run.stderr
    with tifffile.TiffFile(tmp_path / "b.ome.tif") as tif:
        series = tif.series[0]
        # Unsqueezed, as OME orders them (tifffile drops the single channel and the T and S axes otherwise).
        assert series.get_axes(False) == "TCZYXS" and series.get_shape(False) == (1, *data.shape, 1)
        ome = tif.ome_metadata
    for name, value in (("PhysicalSizeX", stack["pixel_size_um"]), ("PhysicalSizeZ", stack["z_step_um"])):
        assert float(ome.split(name + '="')[1].split('"')[0]) == pytest.approx(value, rel=1e-9)


def test_the_docs_numpy_example_runs_as_written(tmp_path, monkeypatch):
    shutil.copytree(SOURCE / "samples" / "lightsheet", tmp_path / "samples" / "lightsheet")
    monkeypatch.chdir(tmp_path)
    namespace = {}
    exec(docs_block("<!-- numpy-example"), namespace)
    ratio = namespace["measured"].sum() / namespace["perfect"].sum()
    assert 0.99 < ratio < 1.0  # clear water: the acquired image keeps all but water's own absorption
    # The 20 uM fibre read at the pixel centres (its peak lies between them).
    assert 15e-6 < namespace["truth"]["concentration"]["alexa_fluor_488"].max() <= 20e-6 * (1 + 1e-6)
