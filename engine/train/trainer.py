"""`lirm train`: one stage of the coarse-to-fine schedule, from one CPU process to many GPUs.

    lirm train --preset tiny --stage 1 --max-steps 50 --out runs/tiny
    torchrun --nproc-per-node 8 -m lirm.engine.cli train --preset small --stage 2 --resume runs/s1/last.safetensors

Per step: every process builds its share of the batch (its own scenes: the data seed includes the
rank), runs the update sets with the loss after each (objective.py), and DDP averages gradients;
AdamW (0.9, 0.95), gradient clipping, cosine learning rate with warm-up, 1/beta linear over the
stage; bf16 autocast and gradient checkpointing on GPUs; the occupancy grid and the numerical-
normal loss in stage 3. Process 0 writes metrics.csv, TensorBoard logs, checkpoints (every
`checkpoint_every` steps, `last.safetensors` and at the end or on Ctrl-C) and periodic held-out
evaluations (eval.csv).

Resuming a checkpoint of the same stage continues the run exactly (weights, AdamW moments, step;
the data of a step depends only on the data seed and the step). A slim copy (the GPU slices')
continues the step with AdamW's second moments from its 8-bit companion when one is beside it, else
with fresh moments and a short learning-rate warm-up. A checkpoint of another stage, or a model-only
checkpoint, starts this stage from its weights.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import signal
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import torch
from torch.utils.data import DataLoader, IterableDataset, get_worker_info

from lirm.engine.errors import LirmUsageError, LirmUserError
from lirm.engine.io.atomic_files import atomic_write, atomic_write_json
from lirm.engine.model.checkpoint import require_safetensors_name
from lirm.engine.model.config import preset as model_preset
from lirm.engine.model.lirm import LIRM
from lirm.engine.model.occupancy_grid import OccupancyConfig
from lirm.engine.synth.training_scenes import GENERATOR_VERSION, TrainingSceneConfig

from .distributed import (ProcessGroupInfo, any_process, finish_together, hardware_description, init_process_group,
                          mean_over_processes, shutdown)
from .losses import LossWeights
from .objective import TrainingObjective
from .perceptual import perceptual_loss
from .scene_source import SceneSource
from .second_moments import second_moments_path
from .stages import StageConfig, stage_config
from .training_checkpoint import load_resume_point, restore_optimizer, save_slim_checkpoint, save_training_checkpoint
from .train_step import train_step, training_optimizer, training_render
from .training_sample import make_sample

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrainConfig:
    preset: str = "tiny"
    stage: int = 1
    out_dir: str = "runs/lirm"
    max_steps: int | None = None  # stop after this step (the schedules still span the whole stage)
    stage_steps: int | None = None  # shorten the stage itself (schedules compressed to it)
    resume: str | None = None
    data_seed: int = 0
    model_seed: int = 0
    scene_pool: int = 0  # 0: a new scene every time; N: draw from N scenes (worth a --cache)
    cache_dir: str | None = None
    scenes: TrainingSceneConfig | None = None  # None: scene_config_for(the preset)
    losses: LossWeights = field(default_factory=LossWeights)
    lpips: bool = True  # use LPIPS when it can run here
    checkpoint_every: int = 100
    eval_every: int = 0  # 0: no periodic evaluation
    eval_objects: int = 2
    eval_size: int | None = None  # held-out views' size; None: the model's input size, at most 128
    workers: int = 0  # data-loader processes rendering scenes
    device: str = "auto"
    max_skipped_steps: int = 20
    batch_scenes: int | None = None  # scenes per step over all processes; None: the stage's
    slim_copy: str | None = None  # also write the last checkpoint here as float16 weights + step, no moments
    # False: only the slim copy, at the same cadence and at the end (a GPU slice's disk is lost after the
    # call, and each full checkpoint with its moments and `last.safetensors` cost it about 10 s of training).
    full_checkpoints: bool = True
    # Gradient checkpointing of the transformer and of the crops' renders: "auto" is on for GPUs (a `small`
    # step of 16 scenes then peaks at 5.8 GiB instead of 115), "off" trades that memory for speed where it
    # fits (1.32 s per step against 2.41 on the H200 of the third slice, `lirm bench train --checkpointing both`).
    checkpointing: str = "auto"

    def uses_checkpointing(self, device: torch.device) -> bool:
        if self.checkpointing not in ("auto", "on", "off"):
            raise LirmUsageError(f"checkpointing {self.checkpointing!r}: choose auto, on or off")
        return device.type == "cuda" if self.checkpointing == "auto" else self.checkpointing == "on"

    def stage_settings(self) -> StageConfig:
        stage = stage_config(self.preset, self.stage)
        if self.stage_steps:
            stage = replace(stage, steps=self.stage_steps, warmup_steps=min(stage.warmup_steps, self.stage_steps // 10))
        if self.batch_scenes:
            stage = replace(stage, batch_scenes=self.batch_scenes)
        return stage

    def to_dict(self) -> dict:
        return asdict(self)


def scene_config_for(image_size: int) -> TrainingSceneConfig:
    """Scenes rendered at the network's input size (supersampled twice: rendering more pixels than
    the crop keeps would be wasted) and environments at a width the lighting needs at that size."""
    return TrainingSceneConfig(size=image_size, environment_width=min(512, max(128, 4 * image_size)))


def learning_rate(stage: StageConfig, step: int) -> float:
    """Linear warm-up, then cosine from the stage's first to its last learning rate."""
    start, end = stage.learning_rate
    if step < stage.warmup_steps:
        return start * (step + 1) / stage.warmup_steps
    progress = min((step - stage.warmup_steps) / max(stage.steps - stage.warmup_steps, 1), 1.0)
    return end + 0.5 * (start - end) * (1.0 + math.cos(math.pi * progress))


# Resuming from a slim checkpoint (no AdamW moments): the second moments start at zero, so the first
# updates would be full-size sign steps; ramp the scheduled rate up over these steps instead.
MOMENT_RESTART_STEPS = 50


def moment_restart_factor(step: int, resumed_at: int) -> float:
    return min(1.0, (step - resumed_at + 1) / MOMENT_RESTART_STEPS)


def inverse_beta(stage: StageConfig, step: int) -> float:
    start, end = stage.inv_beta
    return start + (end - start) * min(step / max(stage.steps - 1, 1), 1.0)


class StopRequests:
    """The SIGINT handler: the first Ctrl-C stops at the end of the step (with a checkpoint); a second
    one interrupts at once, also while the step waits for its data, and the slim copy is still written
    on the way out (a GPU slice's deadline cannot wait for a slow data loader)."""

    def __init__(self) -> None:
        self.requested = False
        self.closing = False  # the run is writing what it leaves behind: a further Ctrl-C must not cut that short

    def __call__(self, *_signal) -> None:
        if self.closing:
            log.warning("already stopping: writing the slim copy and the loss curves first")
            return
        if self.requested:
            raise KeyboardInterrupt("second stop request: interrupting the step")
        self.requested = True
        log.warning("stopping at the end of this step (Ctrl-C again to stop at once, keeping only the slim copy)")


class TrainingStream(IterableDataset):
    """The samples of steps [start, end) for one process; data-loader workers take turns by step,
    so the loader returns them in step order."""

    def __init__(self, source: SceneSource, stage: StageConfig, start: int, end: int, info: ProcessGroupInfo,
                 scenes_here: int, config: TrainConfig):
        self.source, self.stage, self.start, self.end = source, stage, start, end
        self.rank, self.scenes_here, self.config = info.rank, scenes_here, config

    def __iter__(self):
        worker = get_worker_info()
        first, stride = (worker.id, worker.num_workers) if worker else (0, 1)
        for step in range(self.start + first, self.end, stride):
            yield make_sample(self.source, self.stage, step, self.rank, self.scenes_here, self.config.data_seed,
                              self.config.scene_pool)


def _one_thread_per_worker(_worker_id: int) -> None:
    """Each loader process renders on one thread: OpenCV would otherwise start a thread per core in
    every one of them, and the step's own process, launching the GPU's kernels, would wait for a core."""
    import cv2

    cv2.setNumThreads(1)
    torch.set_num_threads(1)


@dataclass
class TrainResult:
    out_dir: Path
    stage: int
    first_step: int
    last_step: int
    history: list[dict]
    stopped_early: bool
    checkpoint: Path | None


class _MetricsCSV:
    def __init__(self, path: Path, columns: list[str], resume_step: int):
        self.path, self.columns = path, columns
        kept = []
        if resume_step > 0 and path.is_file():
            with open(path, newline="") as f:
                kept = [row for row in csv.DictReader(f) if int(row["step"]) <= resume_step]
        text = [",".join(columns)] + [",".join(str(row.get(c, "")) for c in columns) for row in kept]
        # Rows after the checkpoint came from steps that will run again: drop them.
        atomic_write(path, lambda tmp: tmp.write_text("\n".join(text) + "\n"))

    def append(self, record: dict) -> None:
        with open(self.path, "a", newline="") as f:
            csv.writer(f).writerow([_cell(record.get(c, "")) for c in self.columns])


def _cell(value) -> str:
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def _tensorboard(out_dir: Path):
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError as err:
        log.warning("TensorBoard logs skipped (%s); metrics.csv has every number", err)
        return None
    return SummaryWriter(str(out_dir / "tensorboard"))


def run_training(config: TrainConfig, progress: Callable[[dict], None] | None = None,
                 cancel: Callable[[], bool] | None = None) -> TrainResult:
    info = init_process_group(config.device)
    try:
        result = _train(config, info, progress, cancel)
        # Every rank done before any tears its connections down: a rank that destroyed the group while
        # another still wrote its last checkpoint aborted in gloo's teardown once in CI (2026-12-05).
        finish_together(info)
        return result
    finally:
        shutdown(info)


def _prepare_model(config: TrainConfig, stage: StageConfig, info: ProcessGroupInfo) -> tuple[LIRM, int, dict, bool]:
    """The model to train, the step to start at, the resume point's optimizer state (if continuing)
    and whether AdamW starts afresh with a warm-up (a slim checkpoint without its second moments beside it)."""
    if config.resume:
        point = load_resume_point(config.resume, config.preset)  # errors before any compute is spent
        if point.stage == config.stage:
            if point.step >= stage.steps:
                raise LirmUserError(f"checkpoint {config.resume} already finished stage {config.stage} ({point.step} of "
                                    f"{stage.steps} steps); go on with --stage {config.stage + 1} --resume {config.resume}")
            warm_up = point.moments_dropped and not point.second_moments
            if info.is_main:
                how = ""
                if warm_up:
                    how = f" (slim checkpoint: fresh AdamW moments, learning rate warmed up again over {MOMENT_RESTART_STEPS} steps)"
                elif point.moments_dropped:
                    how = " (slim checkpoint: AdamW's second moments restored from beside it, the first afresh; no warm-up)"
                log.info("continuing stage %d from step %d of %s%s", config.stage, point.step, config.resume, how)
            return point.model.train(), point.step, point.optimizer_state, warm_up
        if info.is_main:
            what = f"stage {point.stage}" if point.stage else "model-only"
            log.info("starting stage %d from the weights of %s (%s checkpoint)", config.stage, config.resume, what)
        return point.model.train(), 0, {}, False
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.model_seed)
        model = LIRM(model_preset(config.preset))
    return model.train(), 0, {}, False


def check_scene_views(scenes: TrainingSceneConfig | None, stage: StageConfig, stage_number: int) -> None:
    """Every update set of a step draws its own views of the scene, so a scene must hold them all;
    checked before anything is created or computed."""
    if scenes is None:
        return
    needed = stage.views_per_scene
    if scenes.views < needed:
        raise LirmUsageError(f"--scene-views {scenes.views}: stage {stage_number} feeds {stage.update_sets} update sets "
                             f"of up to {stage.views_per_set[1]} views, so each scene needs at least {needed}")


def _train(config: TrainConfig, info: ProcessGroupInfo, progress, cancel) -> TrainResult:
    stage = config.stage_settings()
    check_scene_views(config.scenes, stage, config.stage)
    if not config.full_checkpoints and not config.slim_copy:
        raise LirmUsageError("without full checkpoints the run needs a slim copy (--slim-copy FILE): nothing would be saved")
    if config.slim_copy:  # found here, not at the first save after minutes of steps
        require_safetensors_name(config.slim_copy)
    out_dir = Path(config.out_dir)
    model, start_step, optimizer_state, fresh_moments = _prepare_model(config, stage, info)
    end_step = min(stage.steps, config.max_steps) if config.max_steps else stage.steps
    if start_step >= end_step:
        raise LirmUserError(f"nothing to do: the run is at step {start_step} and --max-steps is {config.max_steps}")
    device = info.device
    model = model.to(device)
    cuda = device.type == "cuda"
    checkpointing = config.uses_checkpointing(device)
    model.transformer.gradient_checkpointing = checkpointing
    optimizer = training_optimizer(model, stage.learning_rate[0])
    if start_step > 0 and not fresh_moments:  # continuing: the moments must be there (restore_optimizer says so if not)
        restore_optimizer(optimizer, model, optimizer_state, config.resume)
    weights = replace(config.losses, numerical_normal=stage.numerical_normal_weight)
    # With checkpointing the crops' renders are recomputed in the backward pass: without it a `small` step of
    # 16 scenes needs 115 GiB (objective.py).
    objective = TrainingObjective(model, weights, perceptual_loss(config.lpips), render_checkpointing=checkpointing).to(device)
    if info.distributed:
        from torch.nn.parallel import DistributedDataParallel

        step_module = DistributedDataParallel(objective, device_ids=[device.index] if cuda else None)
    else:
        step_module = objective
    scenes_here = max(1, stage.batch_scenes // info.world_size)
    source = SceneSource(config.scenes or scene_config_for(model.config.image_size), model.config.image_size, config.cache_dir)
    loader = DataLoader(TrainingStream(source, stage, start_step, end_step, info, scenes_here, config),
                        batch_size=None, num_workers=config.workers, persistent_workers=False,
                        worker_init_fn=_one_thread_per_worker)
    occupancy = OccupancyConfig(resolution=stage.occupancy_resolution) if stage.occupancy_grid else None
    run = {"config": config.to_dict(), "stage": stage.to_dict(), "generator_version": GENERATOR_VERSION,
           "world_size": info.world_size, "hardware": hardware_description(info),
           "perceptual": type(objective.perceptual).__name__}

    writer, metrics, evaluator = None, None, None
    if info.is_main:
        out_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_json(out_dir / f"stage{config.stage}_run.json", run)
        columns = ["step", "loss", "colour", "albedo", "roughness", "metallic", "normal", "perceptual"]
        columns += ["numerical_normal"] if stage.numerical_normal_weight > 0 else []
        columns += [f"loss_update{u + 1}" for u in range(stage.update_sets)]
        columns += ["lr", "inv_beta", "grad_norm", "skipped", "data_seconds", "step_seconds"]
        metrics = _MetricsCSV(out_dir / "metrics.csv", columns, start_step)
        writer = _tensorboard(out_dir)
        if config.eval_every:
            from .periodic_eval import PeriodicEvaluator

            evaluator = PeriodicEvaluator(out_dir / "eval.csv", config.eval_objects,
                                          config.eval_size or min(128, model.config.image_size), start_step)

    stop = StopRequests()
    previous_handler = None
    try:
        previous_handler = signal.signal(signal.SIGINT, stop)
    except ValueError:  # not the main thread (the app runs training in a worker)
        pass
    history: list[dict] = []
    skipped = 0
    step = start_step
    checkpoint = None
    stopped_early = False
    slim_step = None  # the step of the slim copy last written
    try:
        data_start = time.perf_counter()
        for sample in loader:
            step = sample.step
            data_seconds = time.perf_counter() - data_start
            step_start = time.perf_counter()
            lr = learning_rate(stage, step) * (moment_restart_factor(step, start_step) if fresh_moments else 1.0)
            for group in optimizer.param_groups:
                group["lr"] = lr
            inv_beta = inverse_beta(stage, step)
            render = training_render(stage, inv_beta)
            generator = torch.Generator(device).manual_seed(config.data_seed * 1_000_003 + step * 1009 + info.rank)
            outcome = train_step(step_module, model, optimizer, sample, render, occupancy, generator, device)
            loss, terms, grad_norm = outcome.loss, outcome.terms, outcome.grad_norm
            if not outcome.applied:
                skipped += 1
                if skipped > config.max_skipped_steps:
                    raise FloatingPointError(f"training diverged: {skipped} steps with non-finite loss or gradients "
                                             f"(last at step {step + 1}); resume from an earlier checkpoint with a lower learning rate")
            record = {"step": step + 1, "loss": float(loss.detach()), **terms, "lr": lr, "inv_beta": inv_beta,
                      "grad_norm": float(grad_norm), "skipped": skipped, "data_seconds": data_seconds,
                      "step_seconds": time.perf_counter() - step_start}
            record = {**record, **mean_over_processes({k: v for k, v in record.items() if k not in ("step", "skipped")}, info)}
            history.append(record)
            done = step + 1
            if info.is_main:
                metrics.append(record)
                if writer is not None:
                    for key, value in record.items():
                        if key != "step":
                            writer.add_scalar(f"train/{key}", value, done)
                if progress:
                    progress(record)
            if done % config.checkpoint_every == 0 or done == end_step:
                if config.full_checkpoints:
                    checkpoint = _save(out_dir, model, optimizer, config.stage, done, run, info)
                if info.is_main and config.slim_copy:  # kept current too: a killed run still leaves one to resume from
                    save_slim_checkpoint(Path(config.slim_copy), model, config.stage, done, run, optimizer)
                    slim_step = done
            if evaluator is not None and (done % config.eval_every == 0 or done == end_step):
                evaluator.run(model, done, writer)
                model.train()
            if any_process(stop.requested or bool(cancel and cancel()), info):
                if done % config.checkpoint_every and done != end_step and config.full_checkpoints:
                    checkpoint = _save(out_dir, model, optimizer, config.stage, done, run, info)
                stopped_early = done < end_step
                break
            data_start = time.perf_counter()
    finally:
        # The handler stays until the end: a Ctrl-C that lands here (the first one's step may just have
        # ended) is logged, not raised, so the slim copy a GPU slice depends on is still written.
        stop.closing = True
        try:
            if writer is not None:
                writer.close()
            if info.is_main and config.slim_copy and history:
                if history[-1]["step"] != slim_step:  # a run ending on a checkpoint wrote it there already
                    save_slim_checkpoint(Path(config.slim_copy), model, config.stage, history[-1]["step"], run, optimizer)
                beside = second_moments_path(config.slim_copy)
                log.info("slim checkpoint (float16) of step %d written to %s%s", history[-1]["step"], config.slim_copy,
                         f", AdamW's second moments in 8 bits beside it ({beside.name})" if beside.is_file() else "")
            if info.is_main and (out_dir / "metrics.csv").is_file():
                from .loss_curve import write_loss_curves

                write_loss_curves(out_dir / "metrics.csv", out_dir / "loss_curves.png",
                                  title=f"{config.preset} stage {config.stage}: loss terms per step (log scale)")
            source.release()
            if cuda and info.is_main:
                _log_cuda_memory(device)
        finally:
            if previous_handler is not None:
                signal.signal(signal.SIGINT, previous_handler)
    if not config.full_checkpoints and history and info.is_main:
        checkpoint = Path(config.slim_copy)  # what to resume from: the only checkpoint there is
    return TrainResult(out_dir, config.stage, start_step, history[-1]["step"] if history else start_step, history,
                       stopped_early, checkpoint)


def _log_cuda_memory(device: torch.device) -> None:
    """The run's peak and the caching allocator's retries: each retry frees the cache and synchronises, which
    a step near the GPU's memory with shapes changing from step to step may pay (the H200 slices' steps took
    2.1 s in training against 1.32 s in `lirm bench train`; the slice script sets expandable segments)."""
    try:
        stats = torch.cuda.memory_stats(device)
    except (RuntimeError, AssertionError) as err:  # a report only: never fail a finished run over it
        log.warning("no CUDA memory statistics: %s", err)
        return
    log.info("CUDA memory: peak %.1f GiB allocated, %.1f GiB reserved, %d allocator retries, %d cudaMalloc calls",
             stats.get("allocated_bytes.all.peak", 0) / 2**30, stats.get("reserved_bytes.all.peak", 0) / 2**30,
             stats.get("num_alloc_retries", 0), stats.get("segment.all.allocated", 0))


def _save(out_dir: Path, model: LIRM, optimizer, stage: int, step: int, run: dict, info: ProcessGroupInfo) -> Path | None:
    if not info.is_main:
        return None
    path = save_training_checkpoint(out_dir / f"stage{stage}_step{step:07d}.safetensors", model, optimizer, stage, step, run)
    # last.safetensors: the newest checkpoint under a fixed name (a copy, written atomically).
    atomic_write(out_dir / "last.safetensors", lambda tmp: tmp.write_bytes(path.read_bytes()))
    return path


def describe(result: TrainResult) -> str:
    last = result.history[-1] if result.history else {}
    return json.dumps({"stage": result.stage, "steps": [result.first_step, result.last_step],
                       "loss": last.get("loss"), "checkpoint": str(result.checkpoint) if result.checkpoint else None,
                       "stopped_early": result.stopped_early})
