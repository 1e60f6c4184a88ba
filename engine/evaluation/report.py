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


HEADER = "| PSNR ↑ | SSIM ↑ | LPIPS ↓ | albedo PSNR ↑ | roughness PSNR ↑ | metallic PSNR ↑ | CD ↓ | views |"
NOTES = ("PSNR/SSIM/LPIPS: novel views over white; LPIPS v0.1 with AlexNet. Albedo PSNR after Stanford-ORB's per-channel scale; "
         "roughness, metallic and albedo on the object's pixels. CD: symmetric Chamfer distance of the "
         "marching-cubes mesh to the true surface, in units of the bounding-sphere radius.")


def _cells(r) -> str:
    return (f"{_fmt(r.psnr, 2)} | {_fmt(r.ssim, 3)} | {_fmt(r.lpips, 3)} | {_fmt(r.albedo_psnr, 2)} | "
            f"{_fmt(r.roughness_psnr, 2)} | {_fmt(r.metallic_psnr, 2)} | {_fmt(r.chamfer, 4)} | {r.views} |")


RELIGHT_NOTES = ("Relighting: the exported .glb (mesh, UV atlas, baked textures) rendered by the project's renderer "
                 "under an environment that lit none of the inputs, against the true object under it, after "
                 "Stanford-ORB's per-channel scale. PSNR-H on linear HDR radiance (peak: the truth's brightest "
                 "object pixel) and PSNR-L on the tone-mapped images, both on Stanford-ORB's pixels: the true mask shrunk by "
                 "a margin (5 x 5 at 512 px, scaled to the view), so a missing part costs and the silhouette's exact edge does not; "
                 "SSIM and LPIPS (AlexNet) on the whole tone-mapped images.")


def relighting_section(results: list[tuple[str, EvalResult]]) -> list[str]:
    """The relighting test's table and what lit and relit each object ([] when no row has it)."""
    rows = [(name, r) for name, result in results for r in result.rows if r.relight_psnr_l is not None]
    if not rows:
        return []
    named = any(name for name, _ in rows)  # one model's own table has no reconstructor column
    lines = ["", "Relighting test:", ""]
    lines += (["| reconstructor | after update | PSNR-H ↑ | PSNR-L ↑ | SSIM ↑ | LPIPS ↓ |", "|---|---|---|---|---|---|"] if named
              else ["| after update | PSNR-H ↑ | PSNR-L ↑ | SSIM ↑ | LPIPS ↓ |", "|---|---|---|---|---|"])
    for name, r in rows:
        lines.append((f"| {name} " if named else "") + f"| {r.update} | {_fmt(r.relight_psnr_h, 2)} | "
                     f"{_fmt(r.relight_psnr_l, 2)} | {_fmt(r.relight_ssim, 3)} | {_fmt(r.relight_lpips, 3)} |")
    lines += ["", RELIGHT_NOTES, "", "Lighting per object:"]
    lighting = results[0][1].lighting
    lines += [f"- {obj}: {text}" for obj, text in lighting.items()]
    return lines


def markdown_table(result: EvalResult, title: str | None = None) -> str:
    lines = []
    if title:
        lines += [f"### {title}", ""]
    lines += [f"Set: {result.set_name}, {len(result.objects)} objects ({', '.join(result.objects)}).", ""]
    lines.append("| after update " + HEADER)
    lines.append("|---|---|---|---|---|---|---|---|---|")
    for r in result.rows:
        lines.append(f"| {r.update} | " + _cells(r))
    lines.append("")
    notes = [NOTES]
    if result.lpips_note:
        notes.append(result.lpips_note + ".")
    lines += notes
    lines += relighting_section([("", result)])
    return "\n".join(lines) + "\n"


def comparison_table(results: list[tuple[str, EvalResult]], title: str | None = None) -> str:
    """Several reconstructors scored on the same views, one row per (reconstructor, update), with the
    seconds each took per object (to reconstruct, not to score)."""
    lines = [f"### {title}", ""] if title else []
    first = results[0][1]
    lines += [f"Set: {first.set_name}, {len(first.objects)} objects ({', '.join(first.objects)}); "
              "every row scored on the same input and output views.", ""]
    lines.append("| reconstructor | after update " + HEADER + " seconds |")
    lines.append("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, result in results:
        for r in result.rows:
            lines.append(f"| {name} | {r.update} | " + _cells(r) + f" {_fmt(r.seconds, 1)} |")
    lines += ["", NOTES, "Seconds: the mean time per object to reach that row on this machine (updates, or updates "
              "and refinement), scoring excluded."]
    notes = sorted({result.lpips_note for _, result in results if result.lpips_note})
    lines += [note + "." for note in notes]
    lines += relighting_section(results)
    return "\n".join(lines) + "\n"
