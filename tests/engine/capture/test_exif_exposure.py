"""How each photo was exposed, read from EXIF, and the report's warning when a phone's automatic
exposure moved between shots."""

from __future__ import annotations

import io
import math
import shutil
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from PIL.TiffImagePlugin import IFDRational

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.capture.exif_exposure import exposure_spread, exposure_stops, exposure_stops_of_file
from lirm.engine.cli import main

EXPOSURE_TIME, F_NUMBER, ISO = 0x829A, 0x829D, 0x8827


def _exif(tags: dict[int, object]) -> Image.Exif:
    """EXIF with these exposure tags (fractions and floats written as EXIF rationals, as cameras do)."""
    exif = Image.new("RGB", (1, 1)).getexif()
    as_rational = lambda v: IFDRational(v.numerator, v.denominator) if isinstance(v, Fraction) else (  # noqa: E731
        IFDRational(Fraction(v).limit_denominator(10000).numerator, Fraction(v).limit_denominator(10000).denominator)
        if isinstance(v, float) else v)
    exif.get_ifd(0x8769).update({k: as_rational(v) for k, v in tags.items()})
    return exif


def _jpeg(tags: dict[int, object]) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(np.full((16, 16, 3), 128, np.uint8)).save(buffer, "JPEG", exif=_exif(tags).tobytes())
    return buffer.getvalue()


def test_stops_from_time_iso_and_f_number():
    # An iPhone in daylight: 1/120 s, f/1.6, ISO 32.
    stops = exposure_stops_of_file(_jpeg({EXPOSURE_TIME: Fraction(1, 120), F_NUMBER: 1.6, ISO: 32}))
    assert stops == pytest.approx(math.log2(1 / 120 * 0.32 / 1.6 ** 2), abs=1e-3)
    # Twice the time, or one stop more of ISO, is one stop brighter; a stop of aperture is f-number x 1.414.
    longer = exposure_stops_of_file(_jpeg({EXPOSURE_TIME: Fraction(1, 60), F_NUMBER: 1.6, ISO: 32}))
    wider = exposure_stops_of_file(_jpeg({EXPOSURE_TIME: Fraction(1, 120), F_NUMBER: 1.6 / math.sqrt(2), ISO: 32}))
    assert longer - stops == pytest.approx(1.0, abs=1e-3) and wider - stops == pytest.approx(1.0, abs=1e-2)
    as_tuple = exposure_stops_of_file(_jpeg({EXPOSURE_TIME: Fraction(1, 120), F_NUMBER: 1.6, ISO: (32, 0)}))
    assert as_tuple == pytest.approx(stops)


@pytest.mark.parametrize("tags", [{}, {EXPOSURE_TIME: Fraction(1, 120), F_NUMBER: 1.6},
                                  {EXPOSURE_TIME: 0, F_NUMBER: 1.6, ISO: 32},
                                  {EXPOSURE_TIME: Fraction(1, 120), F_NUMBER: 1.6, ISO: 10 ** 9}])
def test_missing_or_implausible_tags_give_no_figure(tags):
    assert exposure_stops_of_file(_jpeg(tags)) is None


def test_damaged_or_no_image_gives_no_figure():
    assert exposure_stops_of_file(b"not an image") is None
    assert exposure_stops(Image.new("RGB", (4, 4))) is None


def test_the_spread_needs_two_photos():
    assert exposure_spread([None, -6.0]) is None
    assert exposure_spread([-6.0, None, -7.5, -6.2]) == (3, pytest.approx(1.5))


def _lego_with_exposures(shared_data: Path, folder: Path, times: list[float]) -> Path:
    """Lego renders (RGBA PNGs, alpha for masks) tagged as photos taken at these exposure times."""
    folder.mkdir(parents=True)
    for k, seconds in enumerate(times):
        source = shared_data / "synth_nerf_lego_train" / "train" / f"r_{5 * k}.png"
        tags = {EXPOSURE_TIME: Fraction(seconds).limit_denominator(100000), F_NUMBER: 1.8, ISO: 100}
        Image.open(source).save(folder / source.name, exif=_exif(tags).tobytes())
    return folder


@pytest.mark.parametrize("times, warned", [([1 / 100, 1 / 50, 1 / 200, 1 / 100], True), ([1 / 100, 1 / 110, 1 / 100, 1 / 95], False)])
def test_the_capture_report_gives_the_spread_and_warns_when_the_exposure_moved(shared_data, tmp_path, capsys, times, warned):
    photos = _lego_with_exposures(shared_data, tmp_path / "photos", times)
    lego = shared_data / "synth_nerf_lego_train"
    out = tmp_path / "capture"
    assert main(["capture", str(photos), "-o", str(out), "--masks", "alpha", "--size", "32",
                 "--poses", str(lego / "transforms_train.json")]) == 0
    report = capsys.readouterr().out
    spread = math.log2(max(times) / min(times))
    assert f"exposure from EXIF: 4 of 4 photos, {spread:.1f} EV between the brightest and darkest exposed" in report, report
    assert ("lock the exposure" in report) == warned
    if warned:
        assert "4.0 x in brightness" in report
    # Kept in capture.json with each photo: a later report (and a later version's correction) reads it.
    records = Capture.open(out).records
    assert sorted(round(r.exposure_stops, 3) for r in records) == sorted(round(math.log2(t / 1.8 ** 2), 3) for t in times)
    shutil.rmtree(out)
