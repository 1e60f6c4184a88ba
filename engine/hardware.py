"""The name of the device a run used, as benchmarks and training runs record it."""

from __future__ import annotations

import platform

import torch


def device_name(device: torch.device | str = "cpu") -> str:
    """The GPU's name, or the CPU's model name as /proc/cpuinfo gives it (else what `platform` knows)."""
    device = torch.device(device)
    if device.type == "cuda":
        return torch.cuda.get_device_name(device)
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()
