"""`lirm bench exposure`: the exposures and balances a capture reads from its photos' backgrounds,
against a rendered shoot altered with known ones (exposure_bench.py)."""

from __future__ import annotations

import cv2
import pytest

from lirm.engine.bench.exposure_bench import ExposureBenchConfig, run_exposure_bench
from lirm.engine.cli import main


@pytest.mark.slow
def test_the_bench_reads_a_shoot_altered_with_known_exposures_and_tints(tmp_path, shared_data, gl_context):
    from lirm.engine.assets.environment_files import load_environment_file
    from lirm.engine.synth.capture_scene import render_synthetic_capture
    from lirm.renderer.pbr_renderer import PBRRenderer

    renderer = PBRRenderer(gl_context)
    try:
        shoot = render_synthetic_capture(renderer, load_environment_file(shared_data / "envmaps" / "kiara_1_dawn_1k.hdr"))
    finally:
        renderer.release()
    photos = tmp_path / "demo" / "photos"
    photos.mkdir(parents=True)
    for k, image in shoot.images.items():
        cv2.imwrite(str(photos / f"shot_{k}.jpg"), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    result = run_exposure_bench(tmp_path / "demo", ExposureBenchConfig(apart_stops=1.0, tint_stops=0.15, seed=1))
    assert result.photos == 16
    assert not result.control.matched and not result.control.colour_matched, result.report()
    assert result.altered.matched and result.altered.colour_matched, result.report()
    assert result.altered.exposure_error < 0.2 and result.altered.colour_error < 0.04, result.report()
    assert "exposures within" in result.report() and "left alone" in result.report()


def test_the_bench_names_the_fix_for_a_folder_without_a_shoot(tmp_path, capsys):
    assert main(["bench", "exposure", str(tmp_path)]) != 0
    err = capsys.readouterr().err
    assert str(tmp_path) in err and "lirm demo -o" in err
