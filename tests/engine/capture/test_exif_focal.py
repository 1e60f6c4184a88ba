"""The lens's focal length read from EXIF, in the working copy's pixels, as COLMAP's prior."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
from PIL import Image

from lirm.engine.capture.exif_focal import focal_prior_pixels
from lirm.engine.capture.ingest import decode_image


def _jpeg(size: tuple[int, int], tags: dict[int, object], orientation: int = 1) -> bytes:
    exif = Image.new("RGB", (1, 1)).getexif()
    if orientation != 1:
        exif[0x0112] = orientation
    ifd = exif.get_ifd(0x8769)
    ifd.update(tags)
    buffer = io.BytesIO()
    pixels = (np.random.default_rng(0).random((size[1], size[0], 3)) * 255).astype(np.uint8)
    Image.fromarray(pixels).save(buffer, "JPEG", exif=exif.tobytes(), quality=90)
    return buffer.getvalue()


def test_a_phones_35mm_equivalent_gives_its_focal_length_in_pixels():
    # An iPhone's main camera: 26 mm equivalent on a 4032 x 3024 sensor is about 3030 px (measured
    # calibrations of these phones give 2990-3070); the working copy is capped at 1280.
    _, _, focal = decode_image(_jpeg((4032, 3024), {0xA405: 26}), max_side=1280)
    assert focal == pytest.approx(26 / math.hypot(36, 24) * math.hypot(1280, 960), rel=1e-6)
    assert 3030 * 1280 / 4032 == pytest.approx(focal, rel=0.01)


def test_portrait_photos_keep_the_same_focal_length():
    _, _, landscape = decode_image(_jpeg((800, 600), {0xA405: 28}), max_side=1280)
    upright, _, portrait = decode_image(_jpeg((800, 600), {0xA405: 28}, orientation=6), max_side=1280)
    assert upright.shape[:2] == (800, 600) and portrait == pytest.approx(landscape)


def test_focal_length_and_the_sensors_pixel_pitch():
    # 50 mm on a sensor of 4000 px across 23.5 mm (APS-C): 8510 px at full size, 1/5 of it at 800.
    tags = {0x920A: 50.0, 0xA20E: 4000 / 23.5, 0xA210: 4}
    _, _, focal = decode_image(_jpeg((4000, 2667), tags), max_side=800)
    assert focal == pytest.approx(50 * 4000 / 23.5 / 5, rel=1e-4)
    tags_inch = {0x920A: 50.0, 0xA20E: 4000 / 23.5 * 25.4, 0xA210: 2}
    assert decode_image(_jpeg((4000, 2667), tags_inch), max_side=800)[2] == pytest.approx(focal, rel=1e-4)


@pytest.mark.parametrize("tags", [{}, {0xA405: 0}, {0xA405: 1}, {0xA405: 5000}, {0x920A: 50.0}])
def test_missing_or_implausible_tags_give_no_prior(tags):
    # no tag; zero; a 1 mm equivalent (a field of view of 175 degrees); 5 m; a focal length without the pixel pitch
    assert decode_image(_jpeg((640, 480), tags), max_side=1280)[2] is None


def test_damaged_exif_costs_the_prior_not_the_photo():
    class Broken:
        def getexif(self):
            raise ValueError("corrupt EXIF")

    assert focal_prior_pixels(Broken(), (640, 480), (640, 480)) is None
