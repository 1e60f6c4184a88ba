"""Photos in Display P3 (an iPhone's) or another RGB space come into the capture as sRGB."""

from __future__ import annotations

import io
import struct
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageCms

from lirm.engine.capture.colour_profiles import embedded_profile, nclx_space, to_srgb
from lirm.engine.capture.ingest import decode_image
from lirm.engine.capture.photo_formats import enable_heif

D50 = np.array([0.9642, 1.0, 0.8249])
BRADFORD = np.array([[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367], [0.0389, -0.0685, 1.0296]])


def _xy_to_xyz(x: float, y: float) -> np.ndarray:
    return np.array([x / y, 1.0, (1 - x - y) / y])


def _colourants_d50(primaries, white) -> np.ndarray:
    """Columns: each primary's XYZ (scaled so that R + G + B is the white), adapted to D50 (Bradford)."""
    m = np.stack([_xy_to_xyz(*p) for p in primaries], axis=1)
    m = m * np.linalg.solve(m, _xy_to_xyz(*white))
    cone = BRADFORD @ D50 / (BRADFORD @ _xy_to_xyz(*white))
    return np.linalg.inv(BRADFORD) @ np.diag(cone) @ BRADFORD @ m


def _s15(v: float) -> bytes:
    return struct.pack(">i", int(round(v * 65536)))


def matrix_profile(name: str, primaries, white=(0.3127, 0.3290)) -> bytes:
    """A v2 ICC display profile (matrix and the sRGB tone curve), written from the ICC spec: what a
    phone embeds for Display P3."""
    m = _colourants_d50(primaries, white)
    xyz = lambda v: b"XYZ " + bytes(4) + b"".join(_s15(c) for c in v)  # noqa: E731
    ascii_name = name.encode() + b"\0"
    desc = b"desc" + bytes(4) + struct.pack(">I", len(ascii_name)) + ascii_name + bytes(4 + 4 + 2 + 1 + 67)
    curve = b"para" + bytes(4) + struct.pack(">HH", 3, 0) + b"".join(_s15(v) for v in (2.4, 1 / 1.055, 0.055 / 1.055, 1 / 12.92, 0.04045))
    tags = [(b"desc", desc), (b"cprt", b"text" + bytes(4) + b"test\0"), (b"wtpt", xyz(D50)),
            (b"rXYZ", xyz(m[:, 0])), (b"gXYZ", xyz(m[:, 1])), (b"bXYZ", xyz(m[:, 2])),
            (b"rTRC", curve), (b"gTRC", curve), (b"bTRC", curve)]
    offset = 128 + 4 + 12 * len(tags)
    table, body = b"", b""
    for signature, data in tags:
        data += bytes(-len(data) % 4)
        table += signature + struct.pack(">II", offset + len(body), len(data))
        body += data
    size = offset + len(body)
    header = (struct.pack(">I", size) + b"lcms" + struct.pack(">I", 0x02100000) + b"mntrRGB XYZ " + bytes(12) + b"acsp"
              + bytes(4 + 4 + 4 + 4 + 8 + 4) + b"".join(_s15(c) for c in D50) + bytes(4 + 16 + 28))
    assert len(header) == 128
    return header + struct.pack(">I", len(tags)) + table + body


DISPLAY_P3 = matrix_profile("Display P3", [(0.680, 0.320), (0.265, 0.690), (0.150, 0.060)])


def _fox(shared_data: Path) -> np.ndarray:
    path = shared_data / "real_instantngp_fox" / "images" / "0001.jpg"
    if not path.exists():
        pytest.skip(f"{path} missing")
    image = Image.open(path).convert("RGB")
    image.thumbnail((320, 320))
    return np.asarray(image)


def _as_p3(srgb: np.ndarray) -> np.ndarray:
    p3 = ImageCms.ImageCmsProfile(io.BytesIO(DISPLAY_P3))
    return np.asarray(ImageCms.profileToProfile(Image.fromarray(srgb), ImageCms.createProfile("sRGB"), p3, outputMode="RGB"))


def _encode(pixels: np.ndarray, fmt: str, icc: bytes | None) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, fmt, **({"icc_profile": icc} if icc else {}), **({"quality": 95} if fmt in ("JPEG", "HEIF") else {}))
    return buffer.getvalue()


def test_our_display_p3_profile_is_display_p3():
    """The hand-written profile against Display P3's published D50 colourants (Apple's profile:
    red 0.5151 0.2412 -0.0011, green 0.2920 0.6922 0.0419, blue 0.1571 0.0666 0.7841)."""
    m = _colourants_d50([(0.680, 0.320), (0.265, 0.690), (0.150, 0.060)], (0.3127, 0.3290))
    np.testing.assert_allclose(m.T, [[0.5151, 0.2412, -0.0011], [0.2920, 0.6922, 0.0419], [0.1571, 0.0666, 0.7841]], atol=6e-4)


def test_a_display_p3_photo_becomes_the_srgb_picture(shared_data):
    srgb = _fox(shared_data)
    p3 = _as_p3(srgb)
    unconverted = np.abs(p3.astype(float) - srgb)
    assert unconverted.mean() > 2 and unconverted.max() >= 10  # read as sRGB, the P3 pixels are a duller picture
    decoded, _, _ = decode_image(_encode(p3, "PNG", DISPLAY_P3), max_side=1280)
    assert np.abs(decoded.astype(float) - srgb).mean() < 0.5  # 0.11: two 8-bit roundings
    # As a JPEG or an iPhone's HEIC, within what the codec itself costs an sRGB photo (JPEG 1.98 against
    # 1.84, unconverted 3.36; HEIC 1.17 against 1.01).
    assert enable_heif()
    for fmt in ("JPEG", "HEIF"):
        decoded, _, _ = decode_image(_encode(p3, fmt, DISPLAY_P3), max_side=1280)
        baseline, _, _ = decode_image(_encode(srgb, fmt, None), max_side=1280)
        assert np.abs(decoded.astype(float) - srgb).mean() < np.abs(baseline.astype(float) - srgb).mean() + 0.5, fmt


def test_srgb_untagged_and_damaged_profiles_leave_the_pixels_as_stored(shared_data):
    srgb = _fox(shared_data)
    srgb_profile = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    for icc in (None, srgb_profile, b"not an ICC profile at all"):
        decoded, _, _ = decode_image(_encode(srgb, "PNG", icc), max_side=1280)
        assert np.array_equal(decoded, srgb)
    assert embedded_profile(Image.open(io.BytesIO(_encode(srgb, "PNG", srgb_profile)))) is None


def test_alpha_is_kept_through_the_conversion():
    rgba = np.zeros((8, 8, 4), np.uint8)
    rgba[..., 0], rgba[..., 3] = 200, np.arange(8, dtype=np.uint8)[None, :] * 30
    out = to_srgb(rgba, ImageCms.ImageCmsProfile(io.BytesIO(DISPLAY_P3)))
    assert out.shape == (8, 8, 4) and np.array_equal(out[..., 3], rgba[..., 3])
    assert out[0, 0, 0] > 200  # a P3 red of 200 is a more saturated red in sRGB


def _heif_with_nclx(pixels: np.ndarray, primaries: int, transfer: int) -> bytes:
    """A HEIC that states its colours as H.273 codes (an nclx box) and carries no ICC profile, as
    Android phones' and Apple's own encoders write Display P3."""
    assert enable_heif()
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, "HEIF", quality=95, color_primaries=primaries, transfer_characteristics=transfer,
                                 matrix_coefficients=6, full_range_flag=1)
    return buffer.getvalue()


def test_a_heic_that_names_display_p3_by_its_codes_becomes_the_srgb_picture(shared_data):
    srgb = _fox(shared_data)
    p3 = _as_p3(srgb)
    data = _heif_with_nclx(p3, primaries=12, transfer=13)  # 12: P3 primaries with D65 white; 13: the sRGB curve
    opened = Image.open(io.BytesIO(data))
    assert "icc_profile" not in opened.info or not opened.info["icc_profile"]
    space = nclx_space(opened)
    assert space is not None and space.transfer == 13
    # Display P3 -> sRGB, the published matrix (linear light).
    np.testing.assert_allclose(space.rgb_to_srgb_matrix(), [[1.2249, -0.2249, 0.0], [-0.0421, 1.0421, 0.0], [-0.0196, -0.0786, 1.0983]],
                               atol=5e-4)
    decoded, _, _ = decode_image(data, max_side=1280)
    baseline, _, _ = decode_image(_heif_with_nclx(srgb, primaries=1, transfer=13), max_side=1280)
    error = np.abs(decoded.astype(float) - srgb).mean()
    unconverted = np.abs(p3.astype(float) - srgb).mean()
    # Read as sRGB it was the duller picture; converted, within what the codec costs an sRGB photo.
    assert error < np.abs(baseline.astype(float) - srgb).mean() + 0.5 and error < unconverted / 2, (error, unconverted)


def test_nclx_codes_that_are_srgb_hdr_or_unspecified_leave_the_pixels_as_stored(shared_data):
    srgb = _fox(shared_data)
    # 1: BT.709 = sRGB's primaries; 2: unspecified; P3 with PQ (16) is an HDR picture: tone mapping, not a
    # change of primaries, so it is read as before.
    for primaries, transfer in ((1, 13), (2, 2), (12, 16)):
        opened = Image.open(io.BytesIO(_heif_with_nclx(srgb, primaries, transfer)))
        assert nclx_space(opened) is None, (primaries, transfer)
    # BT.2020 primaries with the BT.709 curve (read as sRGB's): converted, and more saturated than stored.
    opened = Image.open(io.BytesIO(_heif_with_nclx(srgb, primaries=9, transfer=1)))
    space = nclx_space(opened)
    assert space is not None
    grey_and_red = to_srgb(np.array([[[128, 128, 128], [180, 60, 40]]], np.uint8), space)
    assert np.abs(grey_and_red[0, 0].astype(int) - 128).max() <= 1  # the same D65 white: greys stay grey
    assert grey_and_red[0, 1, 0] > 180 and grey_and_red[0, 1, 1] < 60


def test_a_damaged_nclx_description_leaves_the_pixels_as_stored():
    image = Image.new("RGB", (4, 4))
    for nclx in ({"color_primaries": 12, "transfer_characteristics": 13}, "not a dict",
                 {"color_primaries": 12, "transfer_characteristics": 13, **{f"color_primary_{k}_{a}": 0.0 for k in ("red", "green", "blue", "white") for a in "xy"}}):
        image.info["nclx_profile"] = nclx
        assert nclx_space(image) is None
