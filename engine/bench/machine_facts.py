"""What a benchmark ran on, recorded beside its figures.

A fit of a fixed number of steps is the same fit twice on one machine, but not across machines: the
CPU's vector kernels (AVX2, AVX-512) and the thread count round sums differently, and a refinement of
1500 steps carries a last-bit difference far (README, "How much one run varies": the same command on
one object gave 22.43, 22.65 and 22.80 dB in three sessions, bit for bit the same twice within each).
So figures are only paired when these facts match.
"""

from __future__ import annotations

import torch

from lirm.engine.hardware import device_name


def machine_facts(device: torch.device | str = "cpu") -> dict:
    """The facts that decide whether two runs of one fit can be bit-for-bit alike."""
    facts = {"device": device_name(device), "torch": torch.__version__, "threads": torch.get_num_threads()}
    if torch.device(device).type == "cpu":
        facts["cpu_kernels"] = torch.backends.cpu.get_cpu_capability()
    return facts


def describe(facts: dict) -> str:
    """One line for a table's foot: 'AMD EPYC (AVX2), 2 threads, torch 2.13.0+cpu'."""
    kernels = f" ({facts['cpu_kernels']})" if facts.get("cpu_kernels") else ""
    return f"{facts['device']}{kernels}, {facts['threads']} threads, torch {facts['torch']}"
