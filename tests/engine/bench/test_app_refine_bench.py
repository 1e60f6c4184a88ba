"""`lirm bench app-refine`: a refinement's steps in the app's window against the same job alone."""

from __future__ import annotations

import hashlib

import pytest

from lirm.engine.bench.app_refine_bench import measure_app_refine, refine_job_args


def _digest(folder) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.slow
def test_the_bench_refines_copies_alone_and_in_the_window_and_leaves_the_capture_alone(lego_capture):
    before = _digest(lego_capture)
    figures = measure_app_refine(lego_capture, seconds=6.0)
    assert figures.alone_steps > 0 and figures.in_app_steps > 0, figures
    assert figures.in_app_wall > 6.0 and figures.alone_wall > 6.0
    text = figures.report()
    assert f"alone {figures.alone_steps} steps" in text and f"in the app {figures.in_app_steps} steps" in text
    assert _digest(lego_capture) == before  # both runs worked on copies


def test_the_job_is_the_refinement_the_app_starts(tmp_path):
    """The arguments the bench runs alone are those the app's Refine button passes (app/actions.py)."""
    import argparse

    from lirm.engine.commands import refine

    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    refine.add_parser(sub)
    args = parser.parse_args(refine_job_args(tmp_path, 30.0))
    assert args.minutes == 0.5 and args.materials and args.live == tmp_path / "app" / "refine_live.safetensors"
