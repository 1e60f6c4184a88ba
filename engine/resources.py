"""Memory a setting needs, checked against the memory there is before any work starts, so that a
setting that cannot fit stops with a sentence (how much it needs, how much is free, the largest value
that fits) instead of a MemoryError minutes later.

The estimates are the bytes the structures of each setting hold at their peak, per unit of the
setting (voxel, pixel, texel), measured as peak RSS growth between two sizes on this project's CPU
machine (2026-11-24; the figure in brackets) and rounded up:

- occupancy grid (reconstruct/refine --grid-resolution; model/occupancy_grid.py): a bool per voxel
  plus the float copy `occupied_fraction` makes [4.2 B/voxel]: 5 B/voxel;
- volume-rendered pictures (--render-size; model/volume_renderer.py render_camera): the pixel rays in
  float64 and float32, every map's chunks and their concatenation, the normalised maps [302 B/px]:
  320 B/px;
- marching-cubes grid (export --grid; export/field_mesh.py, narrow_band.py, marching_cubes.py): the
  float32 SDF grid, its interpolation temporaries, the refined-cell masks, marching cubes' float64
  copy and int64 case codes [33 B/voxel on a sphere; the surface's share grows with the object]:
  40 B/voxel;
- texture baking (export --texture; export/texture_bake.py): the G-buffers read back, the dilated
  maps and the PNG encodings [260 B/texel]: 270 B/texel;
- a prepared crop (capture --size; capture/crop.py prepare_view): crops in float32, the crop
  camera's rays in float64, the Plücker map [181-210 B/px]: 240 B/px.

Plus a fixed WORKING_BYTES for what does not grow with the setting (the network's queries in chunks,
a GL context). Available memory is /proc/meminfo's MemAvailable (Linux); where it cannot be read the
check is skipped rather than guessed.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .errors import LirmResourceError

MEMINFO = Path("/proc/meminfo")
WORKING_BYTES = 256 * 2**20

OCCUPANCY_BYTES_PER_VOXEL = 5
RENDER_BYTES_PER_PIXEL = 320
MESH_GRID_BYTES_PER_VOXEL = 40
BAKE_BYTES_PER_TEXEL = 270
CROP_BYTES_PER_PIXEL = 240


def available_memory_bytes(meminfo: str | Path | None = None) -> int | None:
    """MemAvailable: what can be allocated without swapping; None where it cannot be read."""
    try:
        for line in Path(meminfo or MEMINFO).read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024  # kB
    except (OSError, ValueError, IndexError):
        pass
    return None


def occupancy_grid_bytes(resolution: int) -> int:
    return OCCUPANCY_BYTES_PER_VOXEL * resolution ** 3


def render_bytes(size: int) -> int:
    """One size x size volume-rendered picture (pictures are rendered one after the other)."""
    return RENDER_BYTES_PER_PIXEL * size * size


def mesh_grid_bytes(resolution: int) -> int:
    return MESH_GRID_BYTES_PER_VOXEL * resolution ** 3


def bake_bytes(texture: int) -> int:
    return BAKE_BYTES_PER_TEXEL * texture * texture


def crop_bytes(size: int) -> int:
    return CROP_BYTES_PER_PIXEL * size * size


@dataclass(frozen=True)
class MemoryNeed:
    """The memory one option's value needs, as a function of that value (the other options fixed)."""

    option: str  # "--grid"
    value: int
    bytes_for: Callable[[int], int]
    low: int  # the smallest value the option accepts


def check_memory(command: str, needs: list[MemoryNeed], *, together: bool = True, available: int | None = None) -> int:
    """Raise LirmResourceError when the needs do not fit in the available memory; return the bytes
    needed. `together`: the needs are held at once (summed), else one after the other (the largest).
    The sentence blames the option that needs the most and gives its largest value that fits."""
    available = available_memory_bytes() if available is None else available
    sizes = [n.bytes_for(n.value) for n in needs]
    combine = sum if together else max
    needed = WORKING_BYTES + combine(sizes)
    if available is None or needed <= available:
        return needed
    worst = max(range(len(needs)), key=lambda i: sizes[i])
    blame = needs[worst]
    rest = [s for i, s in enumerate(sizes) if i != worst]

    def fits(value: int) -> bool:
        return WORKING_BYTES + combine(rest + [blame.bytes_for(value)]) <= available

    head = (f"not enough memory for `lirm {command}` with {blame.option} {blame.value}: it needs about "
            f"{format_bytes(needed)}, {format_bytes(available)} is free")
    if not fits(blame.low):
        raise LirmResourceError(f"{head}; even {blame.option} {blame.low} would not fit: close other programs "
                                f"(or lower {', '.join(n.option for n in needs if n is not blame) or 'the other settings'}) "
                                f"and try again")
    lo, hi = blame.low, blame.value  # fits(lo), not fits(hi)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    raise LirmResourceError(f"{head}. The largest {blame.option} that fits is {lo}: lower it to {lo} or less "
                            f"(or close other programs and try again)")


def format_bytes(n: int) -> str:
    return f"{n / 2**20:.0f} MB" if n < 2**30 else f"{n / 2**30:.1f} GB"
