"""The Khronos glTF-Validator (npm package `gltf-validator`, installed by `make setup` into .node/)
run on an exported file: the number of errors and warnings and the messages."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

from lirm.engine.errors import LirmUserError

SCRIPT = Path(__file__).with_name("validate_gltf.js")
REPO_NODE_MODULES = Path(__file__).resolve().parents[2] / ".node" / "node_modules"


@dataclass
class ValidationReport:
    errors: int
    warnings: int
    messages: list[dict]
    raw: dict


def validator_modules() -> Path | None:
    """Where gltf-validator is installed: $LIRM_GLTF_VALIDATOR_MODULES, else the repository's .node/."""
    configured = os.environ.get("LIRM_GLTF_VALIDATOR_MODULES")
    for candidate in ([Path(configured)] if configured else []) + [REPO_NODE_MODULES]:
        if (candidate / "gltf-validator").is_dir():
            return candidate
    return None


def validate_gltf(path: str | Path, timeout: float = 120.0) -> ValidationReport:
    node = shutil.which("node")
    modules = validator_modules()
    if node is None or modules is None:
        raise LirmUserError("the Khronos glTF validator is not installed: run `make setup` (it installs nodejs and "
                            "`npm install --prefix .node gltf-validator`)")
    done = subprocess.run([node, str(SCRIPT), str(modules), str(path)], capture_output=True, text=True, timeout=timeout)
    if done.returncode != 0:
        raise LirmUserError(f"the glTF validator could not read {path}: {done.stderr.strip()[-500:]}")
    raw = json.loads(done.stdout)
    issues = raw.get("issues", {})
    return ValidationReport(int(issues.get("numErrors", 0)), int(issues.get("numWarnings", 0)), issues.get("messages", []), raw)
