"""Reconstruct: the next LIRM update on demand (or automatically), per-scene refinement, their
progress and cost, and the history of updates and refinements to step back through."""

from __future__ import annotations

from imgui_bundle import imgui

from .common import coloured, job_progress


class ReconstructPanel:
    title = "Reconstruct"

    def __init__(self, app):
        self.app = app

    def draw(self) -> None:
        app, state, actions = self.app, self.app.state, self.app.actions
        if state.capture_dir is None:
            imgui.text("Open a capture to reconstruct it.")
            return
        running = app.jobs.running("update")
        refining = app.jobs.running("refine")
        imgui.begin_disabled(bool(running or refining))
        if imgui.button(f"Run update {state.viewing_update + 1}"):
            actions.run_update()
        app.note_widget("run_update")
        imgui.same_line()
        if imgui.button("Refine"):
            actions.run_refine()
        app.note_widget("refine")
        if imgui.is_item_hovered():
            imgui.set_tooltip("Fit the field to all the views for the chosen minutes (per-scene refinement);\n"
                              "the viewport shows it improving; Cancel keeps the best state so far.")
        imgui.same_line()
        imgui.set_next_item_width(110)
        changed, minutes = imgui.slider_float("min##refine", state.choices.refine_minutes, 0.5, 10.0, "%.1f min")
        if changed:
            state.choices.refine_minutes = round(minutes * 2) / 2
            state.save_choices()
        imgui.end_disabled()
        changed, auto = imgui.checkbox("updates automatically as views arrive", state.choices.auto_update)
        if changed:
            state.choices.auto_update = auto
            state.save_choices()
        imgui.text(f"views for it: {', '.join(actions.next_views()) or 'none left'}")
        for job in running + refining + app.jobs.running("preview"):
            job_progress(job, app.jobs.cancel)
        if state.weights:
            coloured(f"weights: {state.weights}", "info" if "UNTRAINED" not in state.weights.upper() else "warning")
        imgui.separator()
        imgui.text("History (click to step back; the next update goes on from there):")
        if imgui.selectable("0: nothing yet", state.viewing_update == 0)[0]:
            actions.step_back(0)
        for u in state.updates:
            cost = state.update_costs.get(u["update"])
            extra = f"; job {cost[0]:.1f} s, {cost[1]:.0f} MB peak" if cost and cost[1] else ""
            if u.get("kind") == "refine":
                label = (f"{u['update']}: refined from {u.get('started_from', '?')}, {len(u['frames'])} views, "
                         f"{u.get('steps', 0)} steps in {u.get('seconds', 0):.0f} s{extra}")
            else:
                label = f"{u['update']}: {len(u['frames'])} views, network {u.get('seconds', 0):.2f} s{extra}  ({', '.join(u['frames'])})"
            if imgui.selectable(label, state.viewing_update == u["update"])[0]:
                actions.step_back(u["update"])
