"""torch.distributed set-up shared by one CPU process, many GPUs and many nodes.

`lirm train` runs as a single process, or under torchrun (which sets RANK, WORLD_SIZE, LOCAL_RANK
and MASTER_ADDR/PORT): NCCL on GPUs, gloo on CPUs. Each process trains on its own scenes (the data
seed includes the rank); DistributedDataParallel averages the gradients.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import torch
import torch.distributed as dist

from lirm.engine.hardware import device_name


@dataclass(frozen=True)
class ProcessGroupInfo:
    rank: int
    world_size: int
    local_rank: int
    device: torch.device

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    @property
    def distributed(self) -> bool:
        return self.world_size > 1


def init_process_group(device: str = "auto") -> ProcessGroupInfo:
    world = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    local = int(os.environ.get("LOCAL_RANK", "0"))
    use_cuda = torch.cuda.is_available() if device == "auto" else device.startswith("cuda")
    if use_cuda:
        torch.cuda.set_device(local)
        dev = torch.device("cuda", local)
    else:
        dev = torch.device("cpu")
    if world > 1 and not dist.is_initialized():
        dist.init_process_group(backend="nccl" if use_cuda else "gloo")
    return ProcessGroupInfo(rank, world, local, dev)


def hardware_description(info: ProcessGroupInfo) -> str:
    """What a run trained on, for its run.json and the model card, e.g. "1 x NVIDIA H100 80GB HBM3"."""
    if info.device.type == "cuda":
        return f"{info.world_size} x {device_name(info.device)}"
    return (f"{info.world_size} process(es) on CPU: {device_name('cpu')}, {os.cpu_count()} cores, "
            f"{torch.get_num_threads()} torch threads")


def finish_together(info: ProcessGroupInfo) -> None:
    """Wait until every process has finished its work (call on the normal path only: after an error the
    other ranks may never arrive)."""
    if info.distributed and dist.is_initialized():
        dist.barrier()


def shutdown(info: ProcessGroupInfo) -> None:
    if info.distributed and dist.is_initialized():
        dist.destroy_process_group()


def mean_over_processes(values: dict[str, float], info: ProcessGroupInfo) -> dict[str, float]:
    """Logged numbers averaged over all processes (every rank must call it with the same keys)."""
    if not info.distributed:
        return values
    keys = sorted(values)
    t = torch.tensor([values[k] for k in keys], dtype=torch.float64,
                     device=info.device if info.device.type == "cuda" else "cpu")
    dist.all_reduce(t)
    return {k: float(v) / info.world_size for k, v in zip(keys, t.tolist())}


def any_process(flag: bool, info: ProcessGroupInfo) -> bool:
    """True on every rank if it is true on any (e.g. a stop request seen by one process)."""
    if not info.distributed:
        return flag
    t = torch.tensor([1.0 if flag else 0.0], device=info.device if info.device.type == "cuda" else "cpu")
    dist.all_reduce(t)
    return bool(t.item() > 0)
