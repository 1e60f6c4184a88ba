"""`lirm bench train`: the seconds of one training step of a preset and stage, what bounds it, and
the step's peak memory, measured on the trainer's own step (train/train_step.py) so that a GPU slice
can be planned from it (README, "Training").

The data is made before the clock starts (a small pool of scenes rendered once, in this process), so
the figure is the network's step alone; the data's own rate is `lirm bench synth`. With `profile`,
one more step runs under torch.profiler and the result lists the operators that took the most time
(device time on a GPU, CPU time on a CPU) and the host time of each part of the step (update, decode,
render and losses over all scenes, backward, optimizer).
"""

from __future__ import annotations

import statistics
import tempfile
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import torch
from torch.autograd import DeviceType

from lirm.engine.errors import LirmUsageError
from lirm.engine.io.atomic_files import atomic_write_json
from lirm.engine.model.config import preset as model_preset
from lirm.engine.model.lirm import LIRM
from lirm.engine.model.occupancy_grid import OccupancyConfig
from lirm.engine.train.losses import LossWeights
from lirm.engine.train.objective import TrainingObjective
from lirm.engine.train.perceptual import perceptual_loss
from lirm.engine.train.scene_source import SceneSource
from lirm.engine.train.stages import stage_config
from lirm.engine.train.train_step import train_step, training_optimizer, training_render
from lirm.engine.train.trainer import check_scene_views, scene_config_for
from lirm.engine.train.training_sample import make_sample

from .machine_facts import device_name
from .model_bench import _resolve_device, _sync
from .peak_memory import PeakMemory

PHASES = ("update", "decode", "render_and_losses", "backward", "optimizer")
CHECKPOINTING = ("auto", "on", "off", "both")


@dataclass(frozen=True)
class TrainBenchConfig:
    preset: str = "small"
    stage: int = 1
    batch_scenes: int | None = None  # None: the stage's
    samples_per_ray: int | None = None  # None: the stage's
    steps: int = 3  # timed steps, after `warmup_steps` that are not counted
    warmup_steps: int = 1
    device: str = "cpu"
    checkpointing: str = "auto"  # of the transformer and the crops' renders: auto (as training: on GPUs), on, off, both
    scene_views: int | None = None  # views rendered per scene; None: the fewest the stage needs
    profile: bool = False
    profile_rows: int = 15
    json_path: Path | None = None
    lpips: bool = True  # the perceptual loss training takes: LPIPS where its weights are, else the substitute


@dataclass
class CheckpointingRun:
    checkpointing: bool
    step_seconds: list[float]
    peak_bytes: int | None
    losses: list[float]

    @property
    def median_seconds(self) -> float:
        return statistics.median(self.step_seconds)


@dataclass
class TrainBenchResult:
    preset: str
    stage: int
    device: str
    batch_scenes: int
    samples_per_ray: int
    rays_per_step: int
    data_seconds_per_scene: float
    perceptual: str = ""  # the perceptual loss in the step (lpips-vgg, or the ms-ssim+gradient substitute)
    runs: list[CheckpointingRun] = field(default_factory=list)
    phases: dict[str, float] = field(default_factory=dict)  # profiled host seconds per part of the step
    top_operators: list[dict] = field(default_factory=list)
    profiled_time: str = ""  # "device" or "cpu"

    def to_dict(self) -> dict:
        out = asdict(self)
        for run, data in zip(self.runs, out["runs"]):
            data["median_seconds"] = run.median_seconds
        return out

    def table(self) -> str:
        lines = [f"training step of '{self.preset}' stage {self.stage} on {self.device}: {self.batch_scenes} scenes, "
                 f"{self.rays_per_step} supervised rays x {self.samples_per_ray} samples; the data made beforehand "
                 f"({self.data_seconds_per_scene:.2f} s per scene in this process); perceptual loss: {self.perceptual}"]
        for run in self.runs:
            memory = f", peak {run.peak_bytes / 2**30:.2f} GiB" if run.peak_bytes else ""
            lines.append(f"  gradient checkpointing {'on ' if run.checkpointing else 'off'}: median {run.median_seconds:.3f} s "
                         f"per step over {len(run.step_seconds)} ({', '.join(f'{s:.3f}' for s in run.step_seconds)}){memory}")
        if self.phases:
            total = sum(self.phases.values()) or 1.0
            lines.append("  profiled step, host time by part (each part's span on the calling thread): " + ", ".join(f"{k} {v:.3f} s ({100 * v / total:.0f}%)" for k, v in self.phases.items()))
        if self.top_operators:
            lines.append(f"  operators by self {self.profiled_time} time in the profiled step:")
            for op in self.top_operators:
                lines.append(f"    {op['seconds']:8.4f} s  {op['calls']:6d} calls  {op['name']}")
        return "\n".join(lines)


def run_train_bench(config: TrainBenchConfig, progress=None) -> TrainBenchResult:
    say = progress or (lambda message: None)
    if config.steps < 1 or config.warmup_steps < 0:
        raise LirmUsageError("the steps must be at least 1 and the warm-up steps at least 0")
    if config.checkpointing not in CHECKPOINTING:
        raise LirmUsageError(f"checkpointing {config.checkpointing!r}: choose one of {', '.join(CHECKPOINTING)}")
    device = _resolve_device(config.device)
    stage = stage_config(config.preset, config.stage)
    batch = config.batch_scenes or stage.batch_scenes
    stage = replace(stage, batch_scenes=batch, samples_per_ray=config.samples_per_ray or stage.samples_per_ray)
    model_config = model_preset(config.preset)
    scenes = replace(scene_config_for(model_config.image_size), views=config.scene_views or stage.views_per_scene)
    check_scene_views(scenes, stage, config.stage)
    torch.manual_seed(0)
    model = LIRM(model_config).to(device).train()
    say(f"rendering {batch} scenes of {scenes.views} views for the steps (not timed)")
    steps = config.warmup_steps + config.steps + (1 if config.profile else 0)
    with tempfile.TemporaryDirectory() as cache:
        source = SceneSource(scenes, model_config.image_size, cache)
        start = time.perf_counter()
        # A pool of `batch` scenes, each rendered once and cached: every step draws its scenes from it.
        try:
            samples = [make_sample(source, stage, step, 0, batch, 0, batch) for step in range(steps)]
        finally:
            source.release()
        data_seconds = (time.perf_counter() - start) / batch
    result = TrainBenchResult(preset=config.preset, stage=config.stage, device=device_name(device), batch_scenes=batch,
                              samples_per_ray=stage.samples_per_ray,
                              rays_per_step=sum(t["origins"].shape[0] for per_update in samples[0].targets for t in per_update),
                              data_seconds_per_scene=data_seconds)
    weights = replace(LossWeights(), numerical_normal=stage.numerical_normal_weight)
    perceptual = perceptual_loss(config.lpips)
    result.perceptual = perceptual.name
    objective = TrainingObjective(model, weights, perceptual).to(device)
    optimizer = training_optimizer(model, 1e-6)  # a small rate: the timed steps barely move the weights
    render = training_render(stage, stage.inv_beta[0])
    occupancy = OccupancyConfig(resolution=stage.occupancy_resolution) if stage.occupancy_grid else None
    settings = {"auto": [device.type == "cuda"], "on": [True], "off": [False], "both": [True, False]}[config.checkpointing]
    meter = PeakMemory(str(device))

    def one_step(sample) -> tuple[float, float]:
        generator = torch.Generator(device).manual_seed(sample.step)
        _sync(device)
        start = time.perf_counter()
        outcome = train_step(objective, model, optimizer, sample, render, occupancy, generator, device)
        _sync(device)
        seconds = time.perf_counter() - start
        return seconds, float(outcome.loss.detach())

    for checkpointing in settings:
        model.transformer.gradient_checkpointing = checkpointing
        objective.render_checkpointing = checkpointing
        say(f"gradient checkpointing {'on' if checkpointing else 'off'}: {config.warmup_steps} warm-up and {config.steps} timed steps")
        for sample in samples[:config.warmup_steps]:
            one_step(sample)
        meter.reset()
        timed = [one_step(sample) for sample in samples[config.warmup_steps:config.warmup_steps + config.steps]]
        peak = meter.peak() if meter.resettable else None
        result.runs.append(CheckpointingRun(checkpointing, [s for s, _ in timed], peak, [loss for _, loss in timed]))
    if config.profile:
        say("one profiled step")
        _profile(result, lambda: one_step(samples[-1]), device, config.profile_rows)
    if config.json_path:
        atomic_write_json(config.json_path, result.to_dict())
    return result


def _profile(result: TrainBenchResult, step, device: torch.device, rows: int) -> None:
    activities = [torch.profiler.ProfilerActivity.CPU]
    if device.type == "cuda":
        activities.append(torch.profiler.ProfilerActivity.CUDA)
    with torch.profiler.profile(activities=activities) as prof:
        step()
    on_device = device.type == "cuda"
    result.profiled_time = "device" if on_device else "cpu"
    averages = prof.key_averages()

    def own(event) -> float:  # microseconds
        return getattr(event, "self_device_time_total", 0.0) if on_device else event.self_cpu_time_total

    # The parts by their host time (the span of each range on the calling thread, children included):
    # the profiler's device time of a range is not reliable for ranges whose kernels run queued behind
    # others, and the backward's kernels are launched by autograd's threads, outside the range. On a
    # GPU a part's host time is the time spent launching its kernels (the bound of a launch-bound step).
    for event in averages:
        if event.key in PHASES:
            result.phases[event.key] = event.cpu_time_total / 1e6
    # Operators only: on a GPU the kernels are listed as events of their own too, and would count twice.
    operators = sorted((e for e in averages if e.key not in PHASES and own(e) > 0 and e.device_type == DeviceType.CPU),
                       key=own, reverse=True)[:rows]
    result.top_operators = [{"name": e.key, "seconds": own(e) / 1e6, "calls": e.count} for e in operators]
