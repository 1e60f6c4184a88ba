"""`lirm bench update-order`: which views go into which update, measured. Each held-out object's 16
input views are taken as a walk-around (sorted by azimuth, as a photographer circling it shoots
them) and split into updates of 4 either in that order (one arc per update) or spread over the
object (farthest-first, `lirm reconstruct`'s default); LIRM and the carved hull are scored after
updates 1-3 on the same output views."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lirm.engine.evaluation.carved_hull import CarvedHull
from lirm.engine.evaluation.evaluate import EvalConfig, evaluate_heldout
from lirm.engine.evaluation.heldout_sets import HeldoutObject
from lirm.engine.reconstruction.session import update_sets


def walk_around(obj: HeldoutObject) -> list[int]:
    """The object's input views in azimuth order."""
    views = [i for s in obj.protocol.input_sets for i in s]
    return sorted(views, key=lambda i: obj.protocol.azimuths_deg[i])


def with_input_sets(obj: HeldoutObject, order: str, views_per_update: int = 4) -> HeldoutObject:
    views = walk_around(obj)
    names = [f"{i:03d}" for i in views]
    cameras = {n: obj.protocol.cameras[i] for n, i in zip(names, views)} if order == "spread" else None
    sets = update_sets(names, views_per_update, None, cameras)
    return replace(obj, protocol=replace(obj.protocol, input_sets=[[int(n) for n in s] for s in sets]))


def run_update_order_bench(model, objects: list[HeldoutObject], config: EvalConfig, progress=None) -> dict:
    reconstructors = {"LIRM": model, "carved hull": CarvedHull(model.config.image_size, radius=model.config.radius)}
    out = {}
    for name, reconstructor in reconstructors.items():
        for order in ("frames", "spread"):
            if progress:
                progress(f"{name}, {order}", len(out), 2 * len(reconstructors))
            chosen = [with_input_sets(o, order) for o in objects]
            result = evaluate_heldout(reconstructor, chosen, config)
            out[f"{name} / {order}"] = [r.to_dict() for r in result.rows]
    return out


def update_order_table(result: dict, objects: list[str]) -> str:
    lines = [f"Update sets in walk-around order (frames) or spread over the object (spread); {len(objects)} objects "
             f"({', '.join(objects)}); means over objects:", "",
             "| reconstructor / order | update | PSNR ↑ | SSIM ↑ | CD ↓ |", "|---|---|---|---|---|"]
    for name, rows in result.items():
        for r in rows:
            chamfer = r["chamfer"] if r["chamfer"] is not None else np.nan
            lines.append(f"| {name} | {r['update']} | {r['psnr']:.2f} | {r['ssim']:.3f} | {chamfer:.4f} |")
    return "\n".join(lines) + "\n"
