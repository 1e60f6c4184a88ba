"""Renderer fixtures: one PBRRenderer for the whole session (program compilation is slow on llvmpipe)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def renderer(gl_context):
    from lirm.renderer.pbr_renderer import PBRRenderer

    r = PBRRenderer(gl_context)
    yield r
    r.release()
