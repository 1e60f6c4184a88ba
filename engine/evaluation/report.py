"""The evaluation as the paper's Markdown table, one row per update."""

from __future__ import annotations

import math

from .evaluate import EvalResult


def _fmt(value: float | None, digits: int) -> str:
    if value is None:
        return "—"
    if math.isinf(value):
        return "∞ (no surface)"
    return f"{value:.{digits}f}"


def markdown_table(result: EvalResult, title: str | None = None) -> str:
    lines = []
    if title:
        lines += [f"### {title}", ""]
    lines += [f"Set: {result.set_name}, {len(result.objects)} objects ({', '.join(result.objects)}).", ""]
    lines.append("| after update | PSNR ↑ | SSIM ↑ | LPIPS ↓ | albedo PSNR ↑ | roughness PSNR ↑ | metallic PSNR ↑ | CD ↓ | views |")
    lines.append("|---|---|---|---|---|---|---|---|---|")
    for r in result.rows:
        lines.append(f"| {r.update} | {_fmt(r.psnr, 2)} | {_fmt(r.ssim, 3)} | {_fmt(r.lpips, 3)} | {_fmt(r.albedo_psnr, 2)} | "
                     f"{_fmt(r.roughness_psnr, 2)} | {_fmt(r.metallic_psnr, 2)} | {_fmt(r.chamfer, 4)} | {r.views} |")
    lines.append("")
    notes = ["PSNR/SSIM: novel views over white. Albedo PSNR after Stanford-ORB's per-channel scale; "
             "roughness, metallic and albedo on the object's pixels. CD: symmetric Chamfer distance of the "
             "marching-cubes mesh to the true surface, in units of the bounding-sphere radius."]
    if result.lpips_note:
        notes.append(result.lpips_note + ".")
    lines += notes
    return "\n".join(lines) + "\n"
