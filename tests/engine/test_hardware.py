"""The device's name, as benchmarks and training runs record it."""

from pathlib import Path

import torch

from lirm.engine.hardware import device_name
from lirm.engine.train.distributed import ProcessGroupInfo, hardware_description


def test_a_cpu_is_named_by_its_model_and_a_training_run_says_so():
    name = device_name("cpu")
    cpuinfo = Path("/proc/cpuinfo")
    models = [line.split(":", 1)[1].strip() for line in cpuinfo.read_text().splitlines()
              if line.startswith("model name")] if cpuinfo.exists() else []
    assert name == (models[0] if models else name) and name.strip()
    info = ProcessGroupInfo(rank=0, world_size=1, local_rank=0, device=torch.device("cpu"))
    assert hardware_description(info).startswith(f"1 process(es) on CPU: {name}, ")
