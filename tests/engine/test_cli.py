"""The `lirm` command line: what a user types, what lands on disk, and clear errors for bad input."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from lirm.engine.cameras import Camera
from lirm.engine.cli import main

LIRM = [sys.executable, "-m", "lirm.engine.cli"]


def run_cli(capsys, *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_help_lists_only_built_subcommands():
    out = subprocess.run([*LIRM, "--help"], capture_output=True, text=True, check=True).stdout
    for command in ("app", "demo", "render", "capture", "reconstruct", "export", "suggest", "train", "curve", "eval", "ship", "bench", "fetch"):
        assert f"    {command} " in out


def test_app_without_a_display_says_what_to_do():
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    done = subprocess.run([*LIRM, "app"], capture_output=True, text=True, env=env)
    assert done.returncode == 3 and "no display" in done.stderr and "lirm demo" in done.stderr


def test_render_builtin_object_writes_every_channel_and_consistent_cameras(tmp_path, capsys):
    out_dir = tmp_path / "mug"
    code, out, err = run_cli(capsys, "render", "mug", "--env", "overcast", "--views", "3", "--size", "80x64",
                             "--supersample", "1", "-o", str(out_dir))
    assert code == 0, err
    assert str(out_dir) in out
    meta = json.loads((out_dir / "transforms.json").read_text())
    assert len(meta["frames"]) == 3
    for frame in meta["frames"]:
        for key in ("file_path", "albedo_file_path", "roughness_file_path", "metallic_file_path", "normal_file_path",
                    "depth_file_path", "mask_path", "radiance_file_path"):
            assert (out_dir / frame[key]).is_file(), key
        beauty = cv2.imread(str(out_dir / frame["file_path"]), cv2.IMREAD_UNCHANGED)
        assert beauty.shape == (64, 80, 3)
        # The camera in transforms.json sees the object where the mask says it is: the normalised
        # object sits at the origin, which projects inside the mask.
        camera = Camera.from_dict({**meta, **frame})
        (x, y), _ = camera.project(np.zeros(3))
        mask = cv2.imread(str(out_dir / frame["mask_path"]), cv2.IMREAD_UNCHANGED)
        assert mask[int(y), int(x)] == 255
        depth = cv2.imread(str(out_dir / frame["depth_file_path"]), cv2.IMREAD_UNCHANGED)
        assert depth.dtype == np.uint16
        z = depth[int(y), int(x)] * meta["depth_unit_scale_factor"]
        assert 0 < z < np.linalg.norm(camera.center)  # the surface is in front of the object's centre


def test_render_under_a_capture_read_through_srgb_shows_it_through_srgb(tmp_path, capsys):
    """`lirm render --env CAPTURE` of a capture on a clipped white backdrop (read through plain sRGB,
    camera_response.py) renders through that curve; the same panorama as a plain .hdr through ACES."""
    import shutil

    from lirm.engine.lighting.capture_lighting import CaptureLighting, CaptureLightingConfig
    from lirm.renderer.procedural_environments import make_procedural_environment

    capture = tmp_path / "capture"
    (capture / "lighting").mkdir(parents=True)
    (capture / "capture.json").write_text("{}")
    observed = np.ones((32, 64))
    CaptureLighting(make_procedural_environment("studio", width=64), observed, np.ones((32, 64)), 4,
                    CaptureLightingConfig(response="srgb")).save(capture)
    shutil.copy(capture / "lighting" / "as_photographed.hdr", tmp_path / "studio_copy.hdr")
    beauty = {}
    for name, env in (("own", capture), ("plain", tmp_path / "studio_copy.hdr")):
        code, out, err = run_cli(capsys, "render", "vase", "--env", str(env), "--views", "1", "--size", "48x48",
                                 "--supersample", "1", "-o", str(tmp_path / name))
        assert code == 0, err
        assert ("shown through plain sRGB" in out) == (name == "own"), out
        beauty[name] = cv2.imread(str(tmp_path / name / "beauty" / "000.png")).astype(int)
    assert np.abs(beauty["own"] - beauty["plain"]).mean() > 5


def test_render_without_background_writes_rgba_with_coverage(tmp_path, capsys):
    code, _, err = run_cli(capsys, "render", "vase", "--views", "1", "--size", "48x48", "--no-background", "-o", str(tmp_path))
    assert code == 0, err
    rgba = cv2.imread(str(tmp_path / "beauty" / "000.png"), cv2.IMREAD_UNCHANGED)
    mask = cv2.imread(str(tmp_path / "mask" / "000.png"), cv2.IMREAD_UNCHANGED)
    assert rgba.shape == (48, 48, 4)
    np.testing.assert_array_equal(rgba[:, :, 3], mask)
    assert rgba[0, 0, 3] == 0 and rgba[24, 24, 3] == 255


def test_render_a_gltf_under_a_real_hdr(tmp_path, capsys, shared_data):
    code, _, err = run_cli(capsys, "render", str(shared_data / "pbr_models" / "Avocado_tex256.glb"),
                           "--env", str(shared_data / "envmaps" / "forest_slope_1k.hdr"), "--views", "2",
                           "--size", "64x64", "-o", str(tmp_path))
    assert code == 0, err
    assert len(list((tmp_path / "beauty").glob("*.png"))) == 2


def test_render_from_given_cameras_keeps_the_asset_in_its_own_frame(tmp_path, capsys, shared_data):
    """Issue 19: an asset and its copy render from the same cameras, view for view (--cameras), and the
    asset is not refitted into the unit sphere (so a reconstruction in the original's frame lines up)."""
    model = str(shared_data / "pbr_models" / "Avocado_tex256.glb")  # a few cm across: far from the unit sphere
    first, again = tmp_path / "first", tmp_path / "again"
    code, _, err = run_cli(capsys, "render", model, "--keep-scale", "--views", "2", "--size", "64x48", "--ibl", "preview",
                           "-o", str(first))
    assert code == 0, err
    code, _, err = run_cli(capsys, "render", model, "--cameras", str(first / "transforms.json"), "--ibl", "preview",
                           "--supersample", "2", "-o", str(again))
    assert code == 0, err
    for k in ("000", "001"):
        a, b = (cv2.imread(str(folder / "beauty" / f"{k}.png")) for folder in (first, again))
        assert a.shape == (48, 64, 3) and np.array_equal(a, b)
    assert json.loads((again / "transforms.json").read_text())["lirm"]["asset_to_world"] == np.eye(4).tolist()
    # A cameras file that is not there is named.
    code, _, err = run_cli(capsys, "render", model, "--cameras", str(tmp_path / "nowhere.json"), "-o", str(tmp_path / "x"))
    assert code == 3 and "nowhere.json: file not found" in err


def _expect_user_error(capsys, *args: str, mentions: str, code: int = 3) -> str:
    """Exit code 3 (bad input) unless told, e.g. 2 for an option out of range."""
    got, _, err = run_cli(capsys, *args)
    assert got == code
    assert "Traceback" not in err
    assert err.startswith("error: ")
    assert mentions in err
    return err


def test_bad_environment_files_are_clear_errors(tmp_path, capsys, shared_data):
    out = str(tmp_path / "out")
    _expect_user_error(capsys, "render", "vase", "--env", str(tmp_path / "nope.hdr"), "-o", out, mentions="nope.hdr")
    truncated = tmp_path / "truncated.hdr"
    data = (shared_data / "envmaps" / "studio_small_03_1k.hdr").read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    _expect_user_error(capsys, "render", "vase", "--env", str(truncated), "-o", out, mentions="truncated.hdr")
    fake = tmp_path / "photo.hdr"
    cv2.imwrite(str(tmp_path / "photo.png"), np.zeros((32, 64, 3), np.uint8))
    shutil.copy(tmp_path / "photo.png", fake)
    _expect_user_error(capsys, "render", "vase", "--env", str(fake), "-o", out, mentions="photo.hdr")
    _expect_user_error(capsys, "render", "vase", "--env", "moonbase", "-o", out, mentions="studio")
    assert not (tmp_path / "out").exists()  # nothing half-written


def test_bad_models_are_clear_errors_and_missing_textures_are_warnings(tmp_path, capsys, shared_data):
    out = str(tmp_path / "out")
    _expect_user_error(capsys, "render", str(tmp_path / "missing.glb"), "-o", out, mentions="missing.glb")
    _expect_user_error(capsys, "render", "teapot", "-o", out, mentions="vase")
    broken = tmp_path / "broken.glb"
    broken.write_bytes((shared_data / "pbr_models" / "Avocado_tex256.glb").read_bytes()[:5000])
    _expect_user_error(capsys, "render", str(broken), "-o", out, mentions="broken.glb")

    helmet = tmp_path / "helmet"
    shutil.copytree(shared_data / "pbr_models" / "DamagedHelmet_gltf", helmet)
    (helmet / "Default_normal.jpg").unlink()
    code, _, err = run_cli(capsys, "render", str(helmet / "DamagedHelmet.gltf"), "--views", "1", "--size", "32x32", "-o", out)
    assert code == 0
    assert "Default_normal.jpg" in err and "WARNING" in err


def test_bad_arguments(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["render", "vase", "--size", "big", "-o", str(tmp_path)])
    assert exc.value.code == 2
    assert "size must look like 512x512" in capsys.readouterr().err
    _expect_user_error(capsys, "render", "vase", "--views", "0", "-o", str(tmp_path), mentions="views", code=2)
    _expect_user_error(capsys, "render", "vase", "--size", "4096x4096", "--supersample", "4", "-o", str(tmp_path),
                       mentions="lower --size or --supersample", code=2)


def test_bench_render_reports_positive_rates(tmp_path, capsys):
    code, out, err = run_cli(capsys, "bench", "render", "--model", "toy_block", "--env", "sky", "--sizes", "32,48",
                             "--frames", "2", "--json", str(tmp_path / "bench.json"))
    assert code == 0, err
    result = json.loads((tmp_path / "bench.json").read_text())
    assert set(result["fps"]) == {"32x32", "48x48"}
    assert all(v["gpu"] > 0 and v["readback"] > 0 for v in result["fps"].values())
    assert result["environment_seconds"]["specular_prefilter"] > 0
    assert "GPU only fps" in out


@pytest.mark.slow
def test_demo_photographs_and_captures_a_builtin_object(tmp_path):
    """`make demo`'s command: renders a built-in object as photos, runs the capture pipeline on them
    and reports pose and mask accuracy against the truth (issue 3's acceptance figures).
    With a 1-minute refinement instead of the default 3: the same flow end to end, two minutes
    sooner (the suite's time); the relit asset's checks below hold there too (worst side 0.92 of
    the original's brightness at 1 minute, 0.95 at 3)."""
    proc = subprocess.run([str(Path(sys.executable).parent / "lirm"), "demo", "-o", str(tmp_path / "demo"), "--refine-minutes", "1"],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "demo output is in" in out
    assert "the material network " in proc.stderr  # the refinement says whether it heard the network, and why
    overview = cv2.imread(str(tmp_path / "demo" / "overview.png"))
    assert overview.shape[0] > 0 and overview.std() > 10  # not a blank sheet
    assert len(list((tmp_path / "demo" / "photos").glob("*.jpg"))) == 16
    assert "posed 16/16 photos" in out, out
    import re

    rotation_max = float(re.search(r"rotation error median [\d.]+ deg, max ([\d.]+) deg", out).group(1))
    centre_max = float(re.search(r"camera-centre error median [\d.]+%, max ([\d.]+)%", out).group(1))
    iou_mean = float(re.search(r"IoU mean ([\d.]+)", out).group(1))
    assert rotation_max < 1.0 and centre_max < 1.0
    # COLMAP's mapping is multi-threaded and not repeatable; before the object's centre followed the
    # cameras' aim, one run in two put it half an object off (IoU 0.57). Now 0.956-0.971 in 5 runs.
    assert iou_mean >= 0.9
    # The mug's handle is a hole through which the floor shows: the masks keep it open (before the
    # floor's agreement, auto_mask.py, every view's mask filled it, and the asset's handle was a disc).
    assert _handle_hole_taken(tmp_path / "demo") < 0.3
    assert len(list((tmp_path / "demo" / "capture" / "prepared").glob("*.npz"))) >= 12
    # It ends with the exported asset, a valid glTF, made with the shipped weights and their caveat.
    from lirm.engine.export.gltf_validation import validate_gltf

    asset = tmp_path / "demo" / "asset.glb"
    assert f"exported asset: {asset}" in out
    report = validate_gltf(asset)
    assert report.errors == 0, report.messages
    assert "shipped checkpoint lirm-tiny.safetensors" in out and "about these weights: " in proc.stderr
    assert "UNTRAINED" not in proc.stderr
    # The built-in mug stated 9.5 cm tall: the glb is in metres, its base on y = 0 (issue 21, cases 8-9),
    # and the USDZ beside it holds the same mesh and textures (case 11).
    import trimesh

    from lirm.engine.export.usdz_writer import read_usdz

    mesh = trimesh.load(asset, force="mesh", process=False)
    assert abs(mesh.bounds[1][1] - mesh.bounds[0][1] - 0.095) < 0.005 and abs(mesh.bounds[0][1]) < 1e-4
    held = read_usdz(asset.with_suffix(".usdz"))
    assert held["vertices"] == len(mesh.vertices) and held["textures"] == ["base_color.png", "metallic_roughness.png", "normal.png"]
    relit = cv2.imread(str(tmp_path / "demo" / "relit.png"))
    assert relit is not None and relit.shape[:2] == (4 * 192, 4 * 192) and relit.std() > 10  # 2 assets x 2 HDRIs, 4 sides
    assert "rows, top to bottom: original mug under studio; exported asset under studio" in out
    # ... and scores it against the original, placed in the shoot's frame (`lirm bench relight`'s figures).
    demo_psnr = float(re.search(r"relit against the original from 8 new views .*?: ([\d.]+) dB \(studio", out).group(1))
    assert 10.0 < demo_psnr < 60.0 and float(re.search(r"silhouette IoU ([\d.]+)", out).group(1)) > 0.85, out
    # The refinement inverse-renders the materials, so the photos' shading is not baked into the albedo:
    # relit, no side of the asset is much darker than the original's (a plain radiance fit's label side,
    # in the sky's shadow in the photos, came out at 0.38-0.47 of the original's brightness; with the
    # materials 0.95-1.39).
    assert "for 1 minute with the materials under the photos' lighting" in proc.stderr
    assert min(_relit_brightness_ratios(relit)) > 0.7, _relit_brightness_ratios(relit)
    # The mug stands on the set's floor: the capture found it as the support plane, and the lighting
    # estimate placed the floor's pixels on it (capture_lighting.py), where the mug sees it.
    assert json.loads((tmp_path / "demo" / "capture" / "lighting" / "lighting.json").read_text())["proxy"] == "support plane and sphere"
    # `lirm bench lighting` compares both lightings of the shoot with the truth (the sky with the lit
    # floor below, truth/lighting.hdr): the backgrounds' estimate, and (--refined) the one the
    # refinement fitted with the materials.
    assert (tmp_path / "demo" / "truth" / "lighting.hdr").is_file()
    for extra, source in (([], "as photographed"), (["--refined"], "fitted with the materials")):
        bench = subprocess.run([str(Path(sys.executable).parent / "lirm"), "bench", "lighting", str(tmp_path / "demo")] + extra,
                               capture_output=True, text=True, timeout=300)
        assert bench.returncode == 0, bench.stderr
        assert source in bench.stdout and "sky over the ground, truth/lighting.hdr" in bench.stdout, bench.stdout
        angle = float(re.search(r"brightest 1%: ([\d.]+) degrees", bench.stdout).group(1))
        ratio = float(re.search(r"upward-facing plane: ([\d.]+) x", bench.stdout).group(1))
        assert 0.0 <= angle <= 180.0 and ratio > 0.0, bench.stdout
    # `lirm bench relight` places the export in the shoot's frame and relights it beside the original.
    picture = tmp_path / "relit-bench.png"
    bench = subprocess.run([str(Path(sys.executable).parent / "lirm"), "bench", "relight", str(tmp_path / "demo"),
                            "--views", "4", "--size", "96", "--picture", str(picture)], capture_output=True, text=True, timeout=300)
    assert bench.returncode == 0, bench.stderr
    assert float(re.search(r"silhouette IoU ([\d.]+)", bench.stdout).group(1)) > 0.85, bench.stdout
    relit_psnrs = [float(v) for v in re.findall(r"PSNR-L ([\d.]+) dB", bench.stdout)]
    assert len(relit_psnrs) == 3 and all(10.0 < v < 60.0 for v in relit_psnrs), bench.stdout  # studio, overcast, mean
    assert cv2.imread(str(picture)) is not None


def _handle_hole_taken(demo: Path) -> float:
    """Of the floor the true masks show through the object (background not joined to the border),
    the share the capture's automatic masks call object, over all photos."""
    from lirm.engine.capture.capture_folder import Capture

    capture = Capture.open(demo / "capture")
    taken = holes_seen = 0
    for frame_id, state in capture.frames.items():
        truth = cv2.imread(str(demo / "truth" / "masks" / f"{state.record.original.stem}.png"), cv2.IMREAD_GRAYSCALE)
        mask = cv2.imread(str(demo / "capture" / "masks" / f"{frame_id}.png"), cv2.IMREAD_GRAYSCALE)
        if truth is None or mask is None:
            continue
        outside = (truth > 127).astype(np.uint8)
        cv2.floodFill(outside, np.zeros((outside.shape[0] + 2, outside.shape[1] + 2), np.uint8), (0, 0), 1)
        holes = outside == 0
        taken += int((mask[holes] > 127).sum())
        holes_seen += int(holes.sum())
    assert holes_seen > 1000  # the handle's hole is seen in several photos
    return taken / holes_seen


def _relit_brightness_ratios(sheet: np.ndarray, tile: int = 192) -> list[float]:
    """Per environment and side: the asset's mean object pixel over the original's on relit.png
    (rows: original, asset, original, asset; the background is the tile's uniform corner)."""
    ratios = []
    for original_row in (0, 2):
        for column in range(sheet.shape[1] // tile):
            means = []
            for row in (original_row, original_row + 1):
                t = sheet[row * tile:(row + 1) * tile, column * tile:(column + 1) * tile].astype(np.float64)
                background = np.median(t[5:20, 5:20].reshape(-1, 3), axis=0)
                means.append(t[np.abs(t - background).sum(-1) > 30].mean())
            ratios.append(means[1] / means[0])
    return ratios
