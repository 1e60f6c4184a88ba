"""Loading HDR environment files: the real Poly Haven .hdr files, EXR round trips, and every way a
file can be bad, each of which must give an EnvironmentLoadError naming the file."""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pytest

from lirm.engine.assets.environment_files import (
    BUILTIN_ENVIRONMENTS,
    load_environment_file,
    resolve_environment,
)
from lirm.engine.errors import EnvironmentLoadError

REAL_HDRS = [
    "dikhololo_night_1k.hdr",
    "forest_slope_1k.hdr",
    "kiara_1_dawn_1k.hdr",
    "st_fagans_interior_1k.hdr",
    "studio_small_03_1k.hdr",
    "venice_sunset_1k.hdr",
]
LUM = np.array([0.2126, 0.7152, 0.0722])


def write_exr(path: Path, channels: dict[str, np.ndarray], header: dict | None = None) -> Path:
    h = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    h.update(header or {})
    OpenEXR.File(h, channels).write(str(path))
    return path


def hdr_bytes(rgb: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".hdr", np.ascontiguousarray(rgb[..., ::-1].astype(np.float32)))
    assert ok
    return buf.tobytes()


@pytest.fixture(scope="module")
def envmaps(shared_data) -> Path:
    return shared_data / "envmaps"


@pytest.fixture(scope="module")
def studio_hdr_bytes(envmaps) -> bytes:
    return (envmaps / "studio_small_03_1k.hdr").read_bytes()


def raises_naming(path: Path, *words: str):
    """Assert the load fails with a message that names the file and says what to do."""
    with pytest.raises(EnvironmentLoadError) as info:
        load_environment_file(path)
    message = str(info.value)
    assert path.name in message
    for w in words:
        assert w in message, message
    return message


# --- real files ------------------------------------------------------------------------------


@pytest.mark.parametrize("name", REAL_HDRS)
def test_real_hdr_loads_as_1k_float_with_hdr_range(envmaps, name):
    env = load_environment_file(envmaps / name)
    r = env.radiance
    assert r.shape == (512, 1024, 3) and r.dtype == np.float32
    assert np.isfinite(r).all() and r.min() >= 0.0
    lum = r @ LUM
    assert lum.max() > 20.0  # real HDR, not a clipped 8-bit image
    assert lum.max() / max(float(np.median(lum)), 1e-6) > 10.0
    # Row 0 is the zenith: every one of these has its lights in the upper half.
    row, _ = np.unravel_index(np.argmax(lum), lum.shape)
    assert row < r.shape[0] // 2
    assert lum[: r.shape[0] // 2].mean() > lum[r.shape[0] // 2 :].mean()
    assert env.name == Path(name).stem


def test_real_hdr_channels_are_rgb_not_bgr(envmaps):
    # A blue-sky forest and a warm tungsten interior: swapping R and B would invert both.
    forest = load_environment_file(envmaps / "forest_slope_1k.hdr").radiance[:256].reshape(-1, 3).mean(0)
    interior = load_environment_file(envmaps / "st_fagans_interior_1k.hdr").radiance.reshape(-1, 3).mean(0)
    assert forest[2] > 1.3 * forest[0]
    assert interior[0] > 1.5 * interior[2]


def test_real_hdr_matches_cv2_reference(envmaps):
    path = envmaps / "venice_sunset_1k.hdr"
    reference = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)[..., ::-1]
    np.testing.assert_array_equal(load_environment_file(path).radiance, reference)


def test_resolve_accepts_paths_and_builtin_names(envmaps, tmp_path):
    assert resolve_environment(str(envmaps / "kiara_1_dawn_1k.hdr")).radiance.shape == (512, 1024, 3)
    assert resolve_environment(envmaps / "kiara_1_dawn_1k.hdr").name == "kiara_1_dawn_1k"
    assert set(BUILTIN_ENVIRONMENTS) == {"studio", "sky", "overcast"}
    for name in BUILTIN_ENVIRONMENTS:
        env = resolve_environment(name, width=64)
        assert env.radiance.shape == (32, 64, 3) and env.name == name
    assert resolve_environment(" Studio ", width=64).name == "studio"


def test_resolve_unknown_name_says_what_to_do(tmp_path):
    for missing in ("beach", str(tmp_path / "gone.hdr")):
        with pytest.raises(EnvironmentLoadError) as info:
            resolve_environment(missing)
        message = str(info.value)
        assert Path(missing).name in message
        assert "studio, sky, overcast" in message and ".hdr or .exr" in message


# --- OpenEXR ---------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", [np.float32, np.float16])
def test_exr_round_trips_exactly(tmp_path, dtype):
    rng = np.random.default_rng(0)
    rgb = (rng.random((32, 64, 3)) * rng.choice([0.01, 1.0, 500.0], size=(32, 64, 1))).astype(dtype)
    path = write_exr(tmp_path / f"env_{np.dtype(dtype).name}.exr", {"RGB": rgb})
    env = load_environment_file(path)
    assert env.radiance.dtype == np.float32 and env.radiance.shape == (32, 64, 3)
    np.testing.assert_array_equal(env.radiance, rgb.astype(np.float32))


def test_exr_alpha_is_ignored_and_y_is_grey(tmp_path):
    rng = np.random.default_rng(1)
    rgba = rng.random((16, 32, 4)).astype(np.float32)
    env = load_environment_file(write_exr(tmp_path / "rgba.exr", {"RGBA": rgba}))
    np.testing.assert_array_equal(env.radiance, rgba[..., :3])

    y = rng.random((16, 32)).astype(np.float16)
    env = load_environment_file(write_exr(tmp_path / "grey.exr", {"Y": y}))
    np.testing.assert_array_equal(env.radiance, np.repeat(y.astype(np.float32)[..., None], 3, axis=-1))


def test_exr_data_window_is_placed_in_the_display_window(tmp_path):
    data = np.full((4, 8), 2.0, dtype=np.float32)
    header = {
        "dataWindow": (np.array([10, 3], np.int32), np.array([17, 6], np.int32)),
        "displayWindow": (np.array([0, 0], np.int32), np.array([31, 15], np.int32)),
    }
    env = load_environment_file(write_exr(tmp_path / "window.exr", {"R": data, "G": data, "B": data}, header))
    assert env.radiance.shape == (16, 32, 3)
    assert (env.radiance[3:7, 10:18] == 2.0).all() and env.radiance.sum() == 2.0 * 3 * data.size


def test_exr_without_colour_channels_is_refused(tmp_path):
    z = np.ones((16, 32), np.float32)
    raises_naming(write_exr(tmp_path / "depth.exr", {"Z": z}), "RGB")


def test_exr_nan_inf_and_negative_texels_are_repaired_with_a_warning(tmp_path, caplog):
    rgb = np.full((16, 32, 3), 0.5, dtype=np.float32)
    rgb[0, 0, 0] = np.nan
    rgb[1, 1, :] = np.nan
    rgb[2, 2, 1] = np.inf
    rgb[3, 3, 2] = -0.25
    rgb[4, 4, 0] = -np.inf
    rgb[5, 5, 0] = 40.0
    path = write_exr(tmp_path / "dirty.exr", {"RGB": rgb})
    with caplog.at_level(logging.WARNING, logger="lirm"):
        env = load_environment_file(path)
    r = env.radiance
    assert np.isfinite(r).all() and r.min() >= 0.0
    assert r[0, 0, 0] == 0.0 and (r[1, 1] == 0.0).all()
    assert r[2, 2, 1] == 40.0  # +Inf -> the largest finite value
    assert r[3, 3, 2] == 0.0 and r[4, 4, 0] == 0.0
    assert r[10, 10, 1] == 0.5
    warnings = [rec for rec in caplog.records if rec.name == "lirm" and rec.levelno == logging.WARNING]
    assert len(warnings) == 1
    text = warnings[0].getMessage()
    assert "dirty.exr" in text and "4 NaN" in text and "1 +Inf" in text and "2 negative" in text


# --- bad files -------------------------------------------------------------------------------


@pytest.mark.parametrize("fraction", [0.5, 0.9])
def test_truncated_hdr_is_refused_not_half_black(tmp_path, studio_hdr_bytes, fraction):
    # OpenCV 5 returns no image for a cut RGBE stream; if a future version returned a partly
    # black one instead, this is where it would show.
    path = tmp_path / f"cut_{int(fraction * 100)}.hdr"
    path.write_bytes(studio_hdr_bytes[: int(len(studio_hdr_bytes) * fraction)])
    raises_naming(path, "truncated", "re-download")


def test_hdr_missing_its_last_bytes_is_refused(tmp_path, studio_hdr_bytes):
    path = tmp_path / "almost.hdr"
    path.write_bytes(studio_hdr_bytes[:-3])
    raises_naming(path, "truncated", "re-download")


def test_hdr_cut_inside_its_header_is_refused(tmp_path, studio_hdr_bytes):
    path = tmp_path / "header_only.hdr"
    path.write_bytes(studio_hdr_bytes[:60])
    raises_naming(path, "re-download")
    path = tmp_path / "no_pixels.hdr"
    path.write_bytes(studio_hdr_bytes[: studio_hdr_bytes.index(b"+X 1024\n") + 8])
    raises_naming(path, "truncated", "re-download")


def test_hdr_with_corrupt_pixel_data_is_refused(tmp_path, studio_hdr_bytes):
    data = bytearray(studio_hdr_bytes)
    mid = len(data) // 2
    data[mid : mid + 4000] = bytes(4000)
    path = tmp_path / "corrupt.hdr"
    path.write_bytes(bytes(data))
    raises_naming(path, "re-download")


@pytest.mark.parametrize("kind", ["png", "jpg"])
def test_8bit_image_renamed_hdr_is_refused(tmp_path, kind):
    img = (np.random.default_rng(0).random((32, 64, 3)) * 255).astype(np.uint8)
    ok, buf = cv2.imencode(f".{kind}", img)
    path = tmp_path / f"photo_{kind}.hdr"
    path.write_bytes(buf.tobytes())
    message = raises_naming(path, ".hdr or .exr")
    assert ("PNG" if kind == "png" else "JPEG") in message


@pytest.mark.parametrize("suffix", [".hdr", ".exr"])
def test_random_bytes_are_refused(tmp_path, suffix):
    path = tmp_path / f"noise{suffix}"
    path.write_bytes(np.random.default_rng(2).bytes(5000))
    raises_naming(path, ".hdr or .exr")


@pytest.mark.parametrize("suffix", [".hdr", ".exr"])
def test_empty_file_is_refused(tmp_path, suffix):
    path = tmp_path / f"empty{suffix}"
    path.write_bytes(b"")
    raises_naming(path, "empty", "re-download")


@pytest.mark.parametrize("tiled", [False, True], ids=["scanline", "tiled"])
@pytest.mark.parametrize("fraction", [0.05, 0.6, 0.999])
def test_truncated_exr_is_refused(tmp_path, tiled, fraction):
    # The binding only prints the read error and hands back an empty File; it must still fail.
    rgb = np.random.default_rng(3).random((64, 128, 3)).astype(np.float32)
    header = {}
    if tiled:
        tiles = OpenEXR.TileDescription()
        tiles.xSize, tiles.ySize, tiles.mode = 16, 16, OpenEXR.ONE_LEVEL
        header = {"type": OpenEXR.tiledimage, "tiles": tiles}
    whole = write_exr(tmp_path / "whole.exr", {"RGB": rgb}, header).read_bytes()
    assert np.array_equal(load_environment_file(tmp_path / "whole.exr").radiance, rgb)
    path = tmp_path / "cut.exr"
    path.write_bytes(whole[: int(len(whole) * fraction)])
    raises_naming(path, "truncated", "re-download")


def test_unsupported_suffix_is_refused(tmp_path):
    img = np.zeros((32, 64, 3), np.uint8)
    path = tmp_path / "sky.png"
    cv2.imwrite(str(path), img)
    raises_naming(path, ".hdr or .exr")
    raises_naming(tmp_path / "sky.jpg", ".hdr or .exr")


def test_missing_file_is_refused(tmp_path):
    raises_naming(tmp_path / "not_here.hdr", "not found", "studio, sky, overcast")


@pytest.mark.parametrize("width, height", [(64, 64), (100, 20), (64, 34)])
def test_non_equirectangular_hdr_is_refused(tmp_path, width, height):
    path = tmp_path / f"crop_{width}x{height}.hdr"
    path.write_bytes(hdr_bytes(np.ones((height, width, 3), np.float32)))
    raises_naming(path, "2:1", f"{width}x{height}")


def test_near_2to1_is_accepted(tmp_path):
    path = tmp_path / "near.hdr"
    path.write_bytes(hdr_bytes(np.ones((31, 64, 3), np.float32)))  # 2.06:1
    assert load_environment_file(path).radiance.shape == (31, 64, 3)


def test_non_equirectangular_exr_is_refused(tmp_path):
    path = write_exr(tmp_path / "square.exr", {"RGB": np.ones((32, 32, 3), np.float32)})
    raises_naming(path, "2:1")


def test_folder_is_refused(tmp_path):
    folder = tmp_path / "dir.hdr"
    folder.mkdir()
    raises_naming(folder, "folder")
