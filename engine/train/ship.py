"""Turn a training run into what ships: fp16 weights without the optimizer state, and a model card
whose facts (preset, data, steps, hardware, hours) are read from the run's own files rather than
typed by hand.

    lirm ship runs/tiny_stage2/last.safetensors --runs runs/tiny runs/tiny_stage2 \\
        --eval runs/eval_synthetic.md --eval runs/eval_gltf.md --notes card_notes.md \\
        --out resources/checkpoints/lirm-tiny.safetensors

The card lands beside the weights as MODEL_CARD.md.
"""

from __future__ import annotations

import csv
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import torch

from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write
from lirm.engine.model.checkpoint import load_checkpoint, peek_checkpoint, save_checkpoint

MAX_SHIPPED_BYTES = 50 * 1024 * 1024  # issue 7: the committed weights stay under 50 MB
CARD_NAME = "MODEL_CARD.md"


@dataclass
class StageRecord:
    """One stage of the run as its files tell it."""

    stage: int
    run_dir: Path
    steps_done: int
    steps_scheduled: int
    compute_hours: float  # sum of the per-step wall times logged in metrics.csv
    loss_first: float | None  # mean loss over the first 100 logged steps
    loss_last: float | None  # ... and over the last 100
    settings: dict  # stageN_run.json

    hardware_override: str | None = None  # what the user says, for runs that predate the record

    @property
    def hardware(self) -> str:
        return self.settings.get("hardware") or self.hardware_override or "not recorded"


def read_stage_record(run_dir: Path, up_to_step: int | None = None) -> StageRecord:
    """The stage run in `run_dir`, counted up to `up_to_step` (the shipped checkpoint's step when the
    run went on after it)."""
    runs = sorted(run_dir.glob("stage*_run.json"))
    if len(runs) != 1:
        raise LirmUserError(f"{run_dir}: expected one stageN_run.json (one stage per run folder), found {len(runs)}")
    settings = json.loads(runs[0].read_text(encoding="utf-8"))
    metrics = run_dir / "metrics.csv"
    if not metrics.is_file():
        raise LirmUserError(f"{run_dir}: no metrics.csv; is this a lirm train output folder?")
    with metrics.open(newline="", encoding="utf-8") as f:
        rows = [r for r in csv.DictReader(f) if up_to_step is None or int(r["step"]) <= up_to_step]
    if not rows:
        raise LirmUserError(f"{metrics} has no steps")
    seconds = sum(float(r.get("step_seconds") or 0) + float(r.get("data_seconds") or 0) for r in rows)

    def mean_loss(part: list[dict]) -> float | None:
        values = [float(r["loss"]) for r in part if r.get("loss")]
        return sum(values) / len(values) if values else None

    return StageRecord(stage=int(settings["stage"]["stage"]), run_dir=run_dir, steps_done=int(rows[-1]["step"]),
                       steps_scheduled=int(settings["stage"]["steps"]), compute_hours=seconds / 3600.0,
                       loss_first=mean_loss(rows[:100]), loss_last=mean_loss(rows[-100:]), settings=settings)


def ship_weights(checkpoint: Path, out: Path, stages: list[StageRecord], note: str = "") -> tuple[Path, dict]:
    """fp16 model weights (no optimizer moments) with the training history in the header."""
    model, extra = load_checkpoint(checkpoint)
    training = extra.get("training") or {}
    metadata = {"trained": True, "source": checkpoint.name, "note": note,
                "training": {"stage": training.get("stage"), "step": training.get("step")},
                "stages": [{"stage": s.stage, "steps": s.steps_done, "of": s.steps_scheduled,
                            "hours": round(s.compute_hours, 3), "hardware": s.hardware} for s in stages]}
    path = save_checkpoint(model, out, dtype=torch.float16, metadata=metadata)
    size = path.stat().st_size
    if size > MAX_SHIPPED_BYTES:
        path.unlink()
        raise LirmUserError(f"{out}: {size / 2**20:.1f} MB is over the {MAX_SHIPPED_BYTES // 2**20} MB that may ship; "
                            f"ship a smaller preset")
    # The fp16 round trip must load and stay finite: the loader refuses NaNs, so this is the check.
    load_checkpoint(path)
    return path, {"parameters": sum(p.numel() for p in model.parameters()), "config": model.config}


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def model_card(weights: Path, info: dict, stages: list[StageRecord], eval_tables: list[str], notes: str, note: str = "") -> str:
    config = info["config"]
    first = stages[0].settings["config"]
    scenes = first.get("scenes") or {}
    lines = [f"# Model card: {weights.name}", "",
             f"LIRM, preset `{config.name}`: width {config.width}, {config.depth} transformer blocks, {config.heads} heads, "
             f"{config.image_size}px inputs in {config.patch}px patches, hexa-plane {config.plane_resolution}², "
             f"colour `{config.colour}`; {info['parameters']:,} parameters.", "",
             f"- File: `{weights.name}`, float16 safetensors, {weights.stat().st_size / 2**20:.2f} MB, "
             f"sha256 `{sha256_of(weights)}`.",
             f"- Config signature (checked on load): `{config.signature()}`.",
             *([f"- Shown to users with every use: \"{note}\""] if note else []), "",
             "## Data", "",
             f"- Synthetic world generator version {stages[0].settings.get('generator_version')}, data seed "
             f"{first.get('data_seed')}, scene pool {first.get('scene_pool') or 'unbounded'} "
             f"(scenes are seeds 0..pool-1; held-out objects use variants training never draws).",
             f"- Objects: {', '.join(scenes.get('objects', [])) or 'built-in'}; environments: "
             f"{', '.join(scenes.get('environments', [])) or 'built-in'}; {scenes.get('views')} views of {scenes.get('size')}px "
             f"per scene, field of view {scenes.get('fov_deg')}°, elevations {scenes.get('elevation_deg')}°.", "",
             "## Training", "",
             "| stage | steps done / scheduled | scenes per step | lr | samples per ray | loss, first → last 100 steps | compute hours | hardware |",
             "|---|---|---|---|---|---|---|---|"]
    for s in stages:
        st = s.settings["stage"]
        loss = (f"{s.loss_first:.3f} → {s.loss_last:.3f}" if s.loss_first is not None and s.loss_last is not None else "—")
        lines.append(f"| {s.stage} | {s.steps_done} / {s.steps_scheduled} | {st['batch_scenes']} | "
                     f"{st['learning_rate'][0]:g} → {st['learning_rate'][1]:g} | {st['samples_per_ray']} | {loss} | "
                     f"{s.compute_hours:.2f} | {s.hardware} |")
    lines += ["", f"Total compute: {sum(s.compute_hours for s in stages):.2f} hours (sum of logged step times; "
              "a stopped-and-resumed stage counts each step once).", ""]
    if eval_tables:
        lines += ["## Evaluation (`lirm eval --baselines`)", ""]
        for table in eval_tables:
            lines += [table.strip(), ""]
    if notes.strip():
        lines += [notes.strip(), ""]
    return "\n".join(lines)


def ship(checkpoint: Path, out: Path, run_dirs: list[Path], eval_paths: list[Path], notes_path: Path | None,
         note: str = "", hardware: str | None = None) -> tuple[Path, Path]:
    for p in [checkpoint, *eval_paths, *([notes_path] if notes_path else [])]:
        if not p.is_file():
            raise LirmUserError(f"{p}: no such file")
    _, extra = peek_checkpoint(checkpoint)
    shipped_at = extra.get("training") or {}
    stages = []
    for d in run_dirs:
        record = read_stage_record(d)
        if record.stage == shipped_at.get("stage"):
            record = read_stage_record(d, int(shipped_at["step"]))
        record.hardware_override = hardware
        stages.append(record)
    stages.sort(key=lambda s: s.stage)
    if not stages:
        raise LirmUserError("name the run folders with --runs (one per stage) so the card can say how the weights were made")
    out.parent.mkdir(parents=True, exist_ok=True)
    weights, info = ship_weights(checkpoint, out, stages, note)
    card = model_card(weights, info, stages, [p.read_text(encoding="utf-8") for p in eval_paths],
                      notes_path.read_text(encoding="utf-8") if notes_path else "", note)
    card_path = out.parent / CARD_NAME
    atomic_write(card_path, lambda tmp: tmp.write_text(card, encoding="utf-8"))
    return weights, card_path
