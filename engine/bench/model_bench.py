"""`lirm bench model`: seconds, peak memory, tokens and FLOPs of the progressive update loop (issue 4).

LIRM reconstructs progressively: every update sees only the state's 3D tokens (hexa-plane + NDE) and the
new views, so its cost is the same for the 1st and the 8th batch of views. The baseline is the MeshLRM
way: all k x views_per_update views in one update, whose tokens, time and memory grow with the views.

Random (seeded, finite) views at the preset's image size, batch 1, in torch.inference_mode(), with the
model's random initial weights (speed and memory do not depend on trained weights). On CUDA the update
runs under bf16 autocast, as the app does on a GPU.

    result = run_model_bench(ModelBenchConfig(preset="small", updates=8), progress=print)
    print(result.table())
"""

from __future__ import annotations

import contextlib
import os
import statistics
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import torch
import torch.nn.functional as F

from lirm.engine.errors import LirmUserError

from .machine_facts import device_name
from .peak_memory import PeakMemory, available_bytes, release_memory

# Dense bf16 tensor-core peaks (no sparsity) from NVIDIA's data sheets, matched in order as substrings of
# torch.cuda.get_device_name(); unknown GPUs get no peak (and so no fraction) unless peak_flops is set.
GPU_PEAK_BF16_FLOPS: tuple[tuple[str, float], ...] = (
    ("H100 PCIe", 756e12),
    ("H100 NVL", 835e12),
    ("H100", 989e12),  # SXM
    ("H200", 989e12),  # also GH200
    ("A100", 312e12),
)


@dataclass
class ModelBenchConfig:
    preset: str = "small"  # model preset: "tiny", "small", "paper"
    updates: int = 8  # timed progressive updates (after one warm-up update that is not counted)
    views_per_update: int = 4
    device: str = "cpu"  # "cpu", "cuda" (an error when no GPU) or "auto" (cuda when available)
    seed: int = 0  # weights and views
    baseline: bool = True  # also time all views in one update, for several view counts
    baseline_updates: tuple[int, ...] | None = None  # k values (k x views_per_update views); None: 1, 2, 4.. and updates
    baseline_max_views: int | None = None  # skip baseline sizes above this many views
    peak_flops: float | None = None  # the device's peak FLOP/s for the fraction; None: look the GPU up
    image_size: int | None = None  # input views of this size instead of the preset's (a multiple of its patch)
    json_path: Path | None = None  # also write the result here (atomically)


@dataclass
class ModelBenchResult:
    preset: str
    device: str
    device_name: str
    dtype: str
    torch_version: str
    threads: int
    image_size: int
    views_per_update: int
    memory_method: str
    memory_note: str
    model: dict = field(default_factory=dict)  # width, depth, heads, parameters, signature
    tokens: dict = field(default_factory=dict)  # one update: {"plane", "nde", "image", "total"}
    flops_per_update: int | None = None
    flops_method: str = ""
    warmup_seconds: float = 0.0
    decode_seconds: float = 0.0
    updates: list[dict] = field(default_factory=list)  # {"update", "seconds", "peak_memory_bytes", ...}
    baseline: list[dict] = field(default_factory=list)  # {"views", "seconds", "peak_memory_bytes", "tokens", ...}
    baseline_skipped: list[dict] = field(default_factory=list)  # {"views", "reason"}
    summary: dict = field(default_factory=dict)
    # 1-minute load average of the machine before and after the run: other work on the CPU slows the timings.
    load_average: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)

    def table(self) -> str:
        mb = 1.0 / 2**20
        t = self.tokens
        s = self.summary
        lines = [
            f"model bench: preset '{self.preset}' (width {self.model.get('width')}, depth {self.model.get('depth')}, "
            f"{self.model.get('parameters', 0) / 1e6:.1f}M parameters)",
            f"device: {self.device} ({self.device_name}), {self.dtype}, {self.threads} CPU threads, torch {self.torch_version}",
            f"tokens per update: plane {t.get('plane')} + NDE {t.get('nde')} + image {t.get('image')} "
            f"({self.views_per_update} views of {self.image_size}x{self.image_size}) = {t.get('total')}",
            f"FLOPs per update: {_flops_text(self.flops_per_update)} ({self.flops_method})",
            f"peak memory: {self.memory_note}",
            f"machine load (1-min average) before / after: {_number(self.load_average.get('before'))} / "
            f"{_number(self.load_average.get('after'))} on {self.load_average.get('cpus')} CPUs",
            "",
            f"progressive updates, {self.views_per_update} new views each (one warm-up update not counted)",
            f"  {'update':>6} {'seconds':>9} {'peak MB':>9} {'+MB':>8} {'state MB':>9}",
        ]
        for r in self.updates:
            lines.append(f"  {r['update']:>6} {r['seconds']:>9.3f} {r['peak_memory_bytes'] * mb:>9.1f} "
                         f"{r['peak_increase_bytes'] * mb:>8.1f} {r['state_storage_bytes'] * mb:>9.2f}")
        growth = s.get("peak_memory_growth")
        lines.append(f"  median {s.get('median_seconds', float('nan')):.3f} s per update; peak memory after update "
                     f"{len(self.updates)} vs after update 1: {_percent(growth)}")
        if s.get("achieved_flops_per_second") is not None:
            rate = f"  achieved {s['achieved_flops_per_second'] / 1e12:.3f} TFLOP/s"
            if s.get("peak_flops_fraction") is not None:
                rate += f" = {100 * s['peak_flops_fraction']:.1f}% of {s['peak_flops'] / 1e12:.0f} TFLOP/s peak"
            lines.append(rate)
        lines.append(f"  decode (planes + NDE panoramas) once: {self.decode_seconds:.3f} s")
        if self.baseline or self.baseline_skipped:
            lines += ["", "baseline: all views in one update from the initial state (the MeshLRM way)",
                      f"  {'views':>6} {'tokens':>8} {'seconds':>9} {'peak MB':>9} {'+MB':>8} {'FLOPs':>12}"]
            for r in self.baseline:
                lines.append(f"  {r['views']:>6} {r['tokens']['total']:>8} {r['seconds']:>9.3f} "
                             f"{r['peak_memory_bytes'] * mb:>9.1f} {r['peak_increase_bytes'] * mb:>8.1f} "
                             f"{_flops_text(r.get('flops')):>12}")
            for r in self.baseline_skipped:
                lines.append(f"  {r['views']:>6} skipped: {r['reason']}")
            if s.get("baseline_seconds_ratio") is not None:
                n = s["baseline_largest_views"]
                lines.append(f"  {n} views at once: {s['baseline_seconds_ratio']:.2f}x the seconds of the progressive "
                             f"updates over the same views, {s['baseline_memory_ratio']:.2f}x their peak memory")
        return "\n".join(lines)


def run_model_bench(config: ModelBenchConfig, progress=None) -> ModelBenchResult:
    say = progress or (lambda message: None)
    from lirm.engine.model.config import preset
    from lirm.engine.model.lirm import LIRM

    if config.updates < 1:
        raise LirmUserError(f"--updates must be at least 1, got {config.updates}")
    if config.views_per_update < 1:
        raise LirmUserError(f"views per update must be at least 1, got {config.views_per_update}")
    try:
        cfg = preset(config.preset)
        if config.image_size:
            cfg = replace(cfg, image_size=config.image_size)
    except ValueError as e:
        raise LirmUserError(str(e)) from None
    device = _resolve_device(config.device)
    cuda = device.type == "cuda"
    meter = PeakMemory(str(device))
    autocast = (lambda: torch.autocast("cuda", dtype=torch.bfloat16)) if cuda else contextlib.nullcontext

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        model = LIRM(cfg).eval().to(device)
    result = ModelBenchResult(
        preset=cfg.name, device=str(device), device_name=device_name(device),
        dtype="bfloat16 (autocast)" if cuda else "float32", torch_version=torch.__version__,
        threads=torch.get_num_threads(), image_size=cfg.image_size, views_per_update=config.views_per_update,
        memory_method=meter.method, memory_note=meter.note,
        model={"width": cfg.width, "depth": cfg.depth, "heads": cfg.heads, "patch": cfg.patch,
               "parameters": sum(p.numel() for p in model.parameters()), "signature": cfg.signature()},
    )
    result.load_average = {"before": _load(), "cpus": os.cpu_count()}
    probe = _TokenProbe(model)
    v = config.views_per_update
    try:
        with torch.inference_mode():
            say(f"warm-up update ({v} views of {cfg.image_size}x{cfg.image_size}, preset '{cfg.name}' on {device})")
            views = _views(cfg, v, config.seed, 0, device)
            state = model.initial_state(1)
            with autocast():
                _, result.warmup_seconds, _, _ = _measured(lambda: model.update(state, views), device, meter)

            say("counting the FLOPs of one update")
            with autocast(), _flop_counter() as counter:
                counted = model.update(state, views)
            result.flops_per_update = int(counter.get_total_flops())
            result.flops_method = f"torch.utils.flop_counter.FlopCounterMode, one update on {device.type}"
            result.tokens = probe.tokens(counted)
            del counted, views, state

            state = model.initial_state(1)
            for i in range(1, config.updates + 1):
                views = _views(cfg, v, config.seed, i - 1, device)
                with autocast():
                    new, seconds, peak, before = _measured(lambda: model.update(state, views), device, meter)
                state = new
                del new, views
                result.updates.append({
                    "update": i, "views": v, "seconds": seconds, "peak_memory_bytes": peak, "memory_before_bytes": before,
                    "peak_increase_bytes": max(0, peak - before), "tokens": probe.tokens(state),
                    "state_bytes": _state_bytes(state, storage=False), "state_storage_bytes": _state_bytes(state, storage=True),
                })
                say(f"update {i}/{config.updates}: {seconds:.3f} s, peak {peak / 2**20:.0f} MB")

            with autocast():
                decoded, result.decode_seconds, _, _ = _measured(lambda: model.decode(state), device, meter)
            del decoded, state
            release_memory(str(device))

            if config.baseline:
                _run_baseline(config, cfg, model, device, meter, autocast, probe, result, say)
    finally:
        probe.remove()

    result.load_average["after"] = _load()
    result.summary = _summary(config, result, device)
    if config.json_path is not None:
        from lirm.engine.io.atomic_files import atomic_write_json

        atomic_write_json(config.json_path, result.to_dict())
    return result


# ---- the baseline ----------------------------------------------------------------------------------------
def baseline_sizes(updates: int) -> tuple[int, ...]:
    """The default k values: 1, 2, 4, ... up to `updates`, and `updates` itself."""
    ks, k = [], 1
    while k <= updates:
        ks.append(k)
        k *= 2
    if ks[-1] != updates:
        ks.append(updates)
    return tuple(ks)


def _run_baseline(config, cfg, model, device, meter, autocast, probe, result, say) -> None:
    v = config.views_per_update
    ks = sorted({k for k in (config.baseline_updates or baseline_sizes(config.updates)) if k >= 1})
    cuda = device.type == "cuda"
    for k in ks:
        n = k * v
        if config.baseline_max_views is not None and n > config.baseline_max_views:
            result.baseline_skipped.append({"views": n, "reason": f"more than baseline_max_views={config.baseline_max_views}"})
            continue
        estimate = estimate_update_bytes(cfg, n, 2 if cuda else 4)
        free = available_bytes(str(device))
        if free is not None and estimate > 0.9 * free:
            result.baseline_skipped.append({"views": n, "reason": f"needs about {estimate / 2**30:.1f} GiB, "
                                                                  f"{free / 2**30:.1f} GiB available"})
            continue
        say(f"baseline: {n} views in one update")
        views = baseline_views(cfg, v, config.seed, k, device)
        state = model.initial_state(1)
        with autocast():
            if cuda:  # new shapes: let the caching allocator and cuBLAS settle first (cheap on a GPU)
                _measured(lambda: model.update(state, views), device, meter)
            out, seconds, peak, before = _measured(lambda: model.update(state, views), device, meter)
        tokens = probe.tokens(out)
        del out, views, state
        release_memory(str(device))
        result.baseline.append({"views": n, "updates_equivalent": k, "seconds": seconds, "peak_memory_bytes": peak,
                                "memory_before_bytes": before, "peak_increase_bytes": max(0, peak - before),
                                "tokens": tokens, "flops": count_update_flops(cfg, n)})
        say(f"baseline {n} views: {seconds:.3f} s, peak {peak / 2**20:.0f} MB")


def estimate_update_bytes(cfg, views: int, element_bytes: int = 4) -> int:
    """A rough floor on one update's working memory: the views, their patches, and one block's activations."""
    h = w = cfg.image_size
    n = cfg.num_plane_tokens + cfg.num_nde_tokens + views * cfg.image_tokens_per_view(h, w)
    inputs = 3 * views * 12 * h * w * 4  # views, their concatenation, the patch permutation
    activations = n * cfg.width * element_bytes * (7 + 2 * cfg.mlp_ratio)  # residual, norm, qkv, attention, MLP
    return int(inputs + activations)


def count_update_flops(cfg, views: int) -> int | None:
    """FLOPs of one update with `views` views, counted by FlopCounterMode on meta tensors (shapes only, no compute).

    Gives the same count as a real update (the tests check it); used for the baseline's large view counts,
    where a real counted run would cost as much as the timed one.
    """
    from lirm.engine.model.lirm import LIRM, ViewBatch

    try:
        with torch.device("meta"):
            meta = LIRM(cfg)
        meta._check = lambda state, views: None  # its isfinite() test needs real data; the timed run checked
        s = cfg.image_size
        batch = ViewBatch(*(torch.empty(1, views, c, s, s, device="meta") for c in (3, 3, 6)))
        with torch.inference_mode(), _flop_counter() as counter:
            meta.update(meta.initial_state(1), batch)
        return int(counter.get_total_flops())
    except Exception:  # a meta kernel missing in some torch build: no count rather than no benchmark
        return None


# ---- helpers -----------------------------------------------------------------------------------------------
def _resolve_device(name: str) -> torch.device:
    name = (name or "cpu").lower()
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name.startswith("cuda"):
        if not torch.cuda.is_available():
            raise LirmUserError("--device cuda: this torch build has no usable CUDA GPU; use --device cpu")
        return torch.device(name)
    if name != "cpu":
        raise LirmUserError(f"unknown device {name!r}; choose cpu, cuda or auto")
    return torch.device("cpu")


def gpu_peak_flops(device_name: str) -> float | None:
    name = device_name.lower()
    for key, flops in GPU_PEAK_BF16_FLOPS:
        if key.lower() in name:
            return flops
    return None


def _load() -> float | None:
    try:
        return os.getloadavg()[0]
    except (OSError, AttributeError):
        return None


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _measured(fn, device: torch.device, meter: PeakMemory):
    """(fn(), wall seconds, peak bytes during it, bytes in use just before it)."""
    release_memory(str(device))
    meter.reset()
    before = meter.current()
    _sync(device)
    start = time.perf_counter()
    out = fn()
    _sync(device)
    seconds = time.perf_counter() - start
    return out, seconds, meter.peak(), before


def _views(cfg, views: int, seed: int, index: int, device):
    """Update `index`'s views: images in [0, 1] and Plücker rays (d, o x d) from cameras 2R from the centre."""
    from lirm.engine.model.lirm import ViewBatch

    g = torch.Generator().manual_seed(seed * 1_000_003 + index)
    s = cfg.image_size
    image = torch.rand(1, views, 3, s, s, generator=g)
    image_bg = torch.rand(1, views, 3, s, s, generator=g)
    origin = F.normalize(torch.randn(1, views, 3, 1, 1, generator=g), dim=2) * 2.0 * cfg.radius
    target = torch.randn(1, views, 3, s, s, generator=g) * 0.3 * cfg.radius
    direction = F.normalize(target - origin, dim=2)
    plucker = torch.cat([direction, torch.cross(origin.expand_as(direction), direction, dim=2)], dim=2)
    return ViewBatch(image.to(device), image_bg.to(device), plucker.to(device))


def baseline_views(cfg, views_per_update: int, seed: int, k: int, device):
    """The views of progressive updates 1..k, all in one batch (so both runs see the same images)."""
    from lirm.engine.model.lirm import ViewBatch

    parts = [_views(cfg, views_per_update, seed, j, "cpu") for j in range(k)]
    return ViewBatch(*(torch.cat([getattr(p, name) for p in parts], dim=1).to(device)
                       for name in ("image", "image_bg", "plucker")))


def _state_bytes(state, storage: bool) -> int:
    tensors = [t for t in (state.plane_tokens, state.nde_tokens) if t is not None]
    if not storage:
        return sum(t.numel() * t.element_size() for t in tensors)
    seen: dict[int, int] = {}
    for t in tensors:  # the state's tensors may be views into one larger output; count what they keep alive
        st = t.untyped_storage()
        seen[st.data_ptr()] = st.nbytes()
    return sum(seen.values())


class _TokenProbe:
    """Counts the tokens the transformer actually sees (a forward pre-hook), split by the state's shapes."""

    def __init__(self, model):
        self.lengths: list[int] = []
        transformer = getattr(model, "transformer", None)
        self.handle = transformer.register_forward_pre_hook(self._hook) if transformer is not None else None

    def _hook(self, module, args):
        self.lengths.append(int(args[0].shape[1]))

    def tokens(self, state) -> dict:
        plane = int(state.plane_tokens.shape[1])
        nde = int(state.nde_tokens.shape[1]) if state.nde_tokens is not None else 0
        total = self.lengths[-1] if self.lengths else plane + nde
        return {"plane": plane, "nde": nde, "image": total - plane - nde, "total": total}

    def remove(self) -> None:
        if self.handle is not None:
            self.handle.remove()


def _flop_counter():
    """FlopCounterMode that also counts torch's CPU flash-attention kernel (not in its registry)."""
    from torch.utils.flop_counter import FlopCounterMode

    def sdpa(query_shape, key_shape, value_shape, *args, out_shape=None, **kwargs) -> int:
        b, h, s_q, d_q = query_shape
        s_k, d_v = key_shape[2], value_shape[3]
        return 2 * b * h * s_q * s_k * d_q + 2 * b * h * s_q * s_k * d_v  # QK^T and (softmax) V

    aten = torch.ops.aten
    extra = {getattr(aten, name): sdpa for name in ("_scaled_dot_product_flash_attention_for_cpu",
                                                    "_scaled_dot_product_fused_attention_overrideable")
             if hasattr(aten, name)}
    return FlopCounterMode(display=False, custom_mapping=extra)


def _summary(config: ModelBenchConfig, result: ModelBenchResult, device: torch.device) -> dict:
    seconds = [r["seconds"] for r in result.updates]
    peaks = [r["peak_memory_bytes"] for r in result.updates]
    s: dict = {
        "median_seconds": statistics.median(seconds),
        "mean_seconds": statistics.fmean(seconds),
        "min_seconds": min(seconds),
        "max_seconds": max(seconds),
        "total_seconds": sum(seconds),
        "peak_memory_bytes": max(peaks),
        "peak_memory_growth": (peaks[-1] / peaks[0] - 1.0) if peaks[0] > 0 else None,
    }
    if result.flops_per_update and s["median_seconds"] > 0:
        s["achieved_flops_per_second"] = result.flops_per_update / s["median_seconds"]
        peak = config.peak_flops
        source = "config"
        if peak is None and device.type == "cuda":
            peak, source = gpu_peak_flops(result.device_name), "bf16 dense table"
        if peak:
            s["peak_flops"] = float(peak)
            s["peak_flops_source"] = source
            s["peak_flops_fraction"] = s["achieved_flops_per_second"] / peak
    if result.baseline:
        first, last = result.baseline[0], result.baseline[-1]
        k = last["updates_equivalent"]
        s["baseline_largest_views"] = last["views"]
        s["baseline_peak_memory_growth"] = last["peak_memory_bytes"] / first["peak_memory_bytes"] - 1.0
        s["baseline_seconds_growth"] = last["seconds"] / first["seconds"] - 1.0 if first["seconds"] > 0 else None
        if k <= len(result.updates):
            progressive = result.updates[:k]
            s["baseline_seconds_ratio"] = last["seconds"] / sum(r["seconds"] for r in progressive)
            s["baseline_memory_ratio"] = last["peak_memory_bytes"] / max(r["peak_memory_bytes"] for r in progressive)
    return s


def _flops_text(flops) -> str:
    if not flops:
        return "n/a"
    for unit, scale in (("TFLOP", 1e12), ("GFLOP", 1e9), ("MFLOP", 1e6)):
        if flops >= scale:
            return f"{flops / scale:.2f} {unit}"
    return f"{flops} FLOP"


def _number(x) -> str:
    return "n/a" if x is None else f"{x:.2f}"


def _percent(x) -> str:
    return "n/a" if x is None else f"{100 * x:+.1f}%"
