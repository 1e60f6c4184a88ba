"""The distribution `lirm`: app/, engine/, renderer/, resources/ install as lirm.* and nothing else."""

from __future__ import annotations

import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FOLDERS = {"app": "lirm.app", "engine": "lirm.engine", "renderer": "lirm.renderer", "resources": "lirm.resources"}
DATA_PACKAGES = {"lirm.renderer.shaders", "lirm.resources.checkpoints"}  # folders of data files only, listed so that setuptools installs them


def test_every_code_folder_is_listed_as_a_package():
    config = tomllib.loads((REPO / "pyproject.toml").read_text())
    listed = set(config["tool"]["setuptools"]["packages"])
    found = set()
    for folder, package in FOLDERS.items():
        for init in (REPO / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(REPO / folder)
            found.add(".".join([package, *rel.parts]))
    for package in DATA_PACKAGES:
        folder, *rest = package.split(".")[1:]
        assert (REPO / folder).joinpath(*rest).is_dir() and not (REPO / folder).joinpath(*rest, "__init__.py").exists(), package
    found |= DATA_PACKAGES
    assert found == listed, f"pyproject.toml packages differ from the folders: missing {found - listed}, stale {listed - found}"


@pytest.mark.slow
def test_wheel_contains_only_the_lirm_namespace_with_its_shaders(tmp_path):
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(tmp_path), str(REPO)],
        check=True, capture_output=True, cwd=tmp_path,
    )
    (wheel,) = tmp_path.glob("lirm-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names}
    assert tops == {"lirm", next(t for t in tops if t.endswith(".dist-info"))}, tops
    assert "lirm/renderer/shaders/mesh_pbr.frag" in names
    assert "lirm/engine/cli.py" in names
    assert "lirm/resources/checkpoints/lirm-tiny.safetensors" in names  # the shipped weights
    assert not [n for n in names if n.endswith("-resume.safetensors") or "training-logs" in n]  # weights in training stay out
    entry_points = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith("entry_points.txt"))).decode()
    assert "lirm = lirm.engine.cli:main" in entry_points


@pytest.mark.slow
def test_plain_install_imports_and_finds_its_shaders(tmp_path):
    target = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "-q", "--target", str(target), str(REPO)],
        check=True, capture_output=True, cwd=tmp_path,
    )
    assert not any((target / name).exists() for name in FOLDERS), "a bare app/engine/renderer landed in site-packages"
    code = (
        "import lirm.renderer.shader_source as s, lirm.engine.cli, lirm.app, lirm.resources;"
        "assert 'vec3' in s.shader_source('mesh_pbr.frag');"
        "from lirm.engine.model.pretrained import shipped_checkpoint;"
        "assert shipped_checkpoint('tiny') is not None;"
        "assert not list(shipped_checkpoint('tiny').parent.glob('*-resume.safetensors'));"
        "print(s.SHADER_DIR)"
    )
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, cwd=tmp_path,
                         env={"PYTHONPATH": str(target), "PATH": "/usr/bin:/bin"})
    assert str(target) in out.stdout
