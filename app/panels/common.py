"""Small drawing helpers the panels share."""

from __future__ import annotations

from imgui_bundle import imgui

from lirm.app.jobs import Job

COLOURS = {"error": imgui.ImVec4(1.0, 0.45, 0.4, 1.0), "warning": imgui.ImVec4(1.0, 0.8, 0.35, 1.0),
           "info": imgui.ImVec4(0.85, 0.85, 0.85, 1.0), "ok": imgui.ImVec4(0.55, 0.9, 0.55, 1.0)}


def job_progress(job: Job, cancel) -> None:
    """A progress bar with the job's stage and a Cancel button."""
    fraction = job.fraction if job.total else (imgui.get_time() * 0.5) % 1.0  # no total yet: keep moving
    imgui.progress_bar(fraction, imgui.ImVec2(-90, 0), f"{job.stage} ({job.seconds:.0f} s)")
    imgui.same_line()
    if imgui.button(f"Cancel##{id(job)}"):
        cancel(job)


def saved_choice_checkbox(state, label: str, choice: str, tip: str | None = None) -> None:
    """A checkbox on one of the capture's saved choices (`state.choices.<choice>`), saved when clicked."""
    changed, value = imgui.checkbox(label, getattr(state.choices, choice))
    if changed:
        setattr(state.choices, choice, value)
        state.save_choices()
    if tip and imgui.is_item_hovered(imgui.HoveredFlags_.for_tooltip):
        imgui.set_tooltip(tip)


def coloured(text: str, level: str) -> None:
    imgui.text_colored(COLOURS.get(level, COLOURS["info"]), text)


def short_status(status: str, longest: int = 16) -> str:
    """A status's head for a narrow table column: the words before its reason ("left out: its pose
    disagreed ..." -> "left out", "not registered (too few ...)" -> "not registered"). Where even the
    head is long it says only that something is wrong ("not posed" / "not usable"), since one long
    reason in a fitted column took the whole width and cut every photo's name to two letters; the
    whole reason is the cell's tooltip."""
    head = status.split(":", 1)[0].split(" (", 1)[0].strip()
    return head if 0 < len(head) <= longest else ""


def format_seconds(seconds: float) -> str:
    """A short duration as a person reads it: "0.41 s", and "6 ms" rather than "0.00 s" (the tiny
    network's update takes a few milliseconds once torch is warm)."""
    return f"{1000 * seconds:.0f} ms" if seconds < 0.1 else f"{seconds:.2f} s"
