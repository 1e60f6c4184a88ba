"""Fixtures shared by all tests: the real test data beside the repository, and GL contexts."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("LIRM_SHARED_DATA", REPO_ROOT.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data (or $LIRM_SHARED_DATA); tests that need it skip with the reason when absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real test data not found at {SHARED_DATA} (set LIRM_SHARED_DATA)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def gl_context():
    """One headless EGL context for the whole session (creating contexts is slow on llvmpipe)."""
    from lirm.renderer.context import create_headless_context

    ctx = create_headless_context()
    yield ctx
    ctx.release()
