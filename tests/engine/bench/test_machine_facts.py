import torch

from lirm.engine.bench.machine_facts import describe, machine_facts
from lirm.engine.hardware import device_name


def test_the_facts_name_this_cpu_its_kernels_threads_and_torch():
    facts = machine_facts("cpu")
    assert facts["device"] == device_name("cpu") and facts["device"].strip()
    assert facts["threads"] == torch.get_num_threads()
    assert facts["torch"] == torch.__version__
    # torch.backends.cpu.get_cpu_capability's documented values.
    assert facts["cpu_kernels"] in ("DEFAULT", "VSX", "Z VECTOR", "NO AVX", "AVX2", "AVX512", "SVE256")
    line = describe(facts)
    assert line.startswith(facts["device"]) and f"({facts['cpu_kernels']})" in line
    assert f"{facts['threads']} threads, torch {facts['torch']}" in line


def test_a_gpu_line_has_no_cpu_kernels():
    assert describe({"device": "NVIDIA H200", "threads": 16, "torch": "2.13.0"}) == "NVIDIA H200, 16 threads, torch 2.13.0"
