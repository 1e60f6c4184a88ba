"""Peak memory of a stretch of code: resettable, so each measured step gets its own peak.

    meter = PeakMemory("cpu")        # or "cuda"
    release_memory("cpu")            # gc, return freed heap to the OS
    meter.reset()
    ...                              # the measured step
    meter.peak()                     # bytes, highest since reset()

Methods (`meter.method`):
  "vmhwm"        Linux: peak resident set size of the whole process. Writing "5" to /proc/self/clear_refs
                 resets the kernel's high-water mark (VmHWM in /proc/self/status) to the current RSS.
  "ru_maxrss"    fallback where clear_refs is not writable: resource.getrusage's peak RSS, which cannot be
                 reset, so it is the highest of the whole process life so far, not of the step alone.
  "cuda_max_memory_allocated"  torch.cuda.max_memory_allocated after torch.cuda.reset_peak_memory_stats:
                 tensor memory on the GPU (not the CUDA context, not the caching allocator's slack).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import resource
import sys

_STATUS = "/proc/self/status"
_CLEAR_REFS = "/proc/self/clear_refs"

METHOD_NOTES = {
    "vmhwm": "process peak RSS (VmHWM), reset before each step via /proc/self/clear_refs",
    "ru_maxrss": "process peak RSS from getrusage (cannot be reset: the lifetime peak up to each step)",
    "cuda_max_memory_allocated": "torch.cuda.max_memory_allocated, reset before each step (tensor memory only)",
}


def _status_kb(field: str) -> int | None:
    try:
        with open(_STATUS) as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        return None
    return None


def _clear_refs() -> bool:
    try:
        with open(_CLEAR_REFS, "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _ru_maxrss_bytes() -> int:
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak) if sys.platform == "darwin" else int(peak) * 1024  # bytes on macOS, KiB on Linux


class PeakMemory:
    """Peak memory of one device since the last reset(); see the module notes for the methods."""

    def __init__(self, device: str = "cpu"):
        self.device = str(device)
        if self.device.startswith("cuda"):
            self.method = "cuda_max_memory_allocated"
        elif _status_kb("VmHWM") is not None and _clear_refs():
            self.method = "vmhwm"
        else:
            self.method = "ru_maxrss"

    @property
    def note(self) -> str:
        return METHOD_NOTES[self.method]

    @property
    def resettable(self) -> bool:
        return self.method != "ru_maxrss"

    def reset(self) -> None:
        if self.method == "cuda_max_memory_allocated":
            import torch

            torch.cuda.synchronize(self.device)
            torch.cuda.reset_peak_memory_stats(self.device)
        elif self.method == "vmhwm":
            _clear_refs()

    def current(self) -> int:
        """Memory in use now, in bytes: RSS (CPU) or allocated tensor memory (CUDA)."""
        if self.method == "cuda_max_memory_allocated":
            import torch

            return int(torch.cuda.memory_allocated(self.device))
        rss = _status_kb("VmRSS")
        return rss * 1024 if rss is not None else _ru_maxrss_bytes()

    def peak(self) -> int:
        """Highest memory since reset(), in bytes (ru_maxrss: since the process started)."""
        if self.method == "cuda_max_memory_allocated":
            import torch

            torch.cuda.synchronize(self.device)
            return int(torch.cuda.max_memory_allocated(self.device))
        if self.method == "vmhwm":
            hwm = _status_kb("VmHWM")
            if hwm is not None:
                return hwm * 1024
        return _ru_maxrss_bytes()


_libc = None


def _malloc_trim() -> None:
    """Give glibc's freed heap back to the OS, so the next step's RSS starts from what is really live."""
    global _libc
    if not sys.platform.startswith("linux"):
        return
    try:
        if _libc is None:
            _libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        _libc.malloc_trim(0)
    except (OSError, AttributeError):
        pass


def release_memory(device: str = "cpu") -> None:
    """Free what is no longer referenced before a measurement: gc, malloc_trim, the CUDA cache."""
    gc.collect()
    if str(device).startswith("cuda"):
        import torch

        torch.cuda.synchronize(device)
        torch.cuda.empty_cache()
    else:
        _malloc_trim()


def available_bytes(device: str = "cpu") -> int | None:
    """Memory that could still be allocated: MemAvailable (CPU) or free GPU memory; None if unknown."""
    if str(device).startswith("cuda"):
        import torch

        return int(torch.cuda.mem_get_info(device)[0])
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None
