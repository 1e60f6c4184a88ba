"""Reconstruct: the next LIRM update on demand (or automatically), per-scene refinement, their
progress and cost, and the history of updates and refinements to step back through."""

from __future__ import annotations

from imgui_bundle import imgui

from .common import coloured, format_seconds, job_progress, saved_choice_checkbox


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
        next_views = actions.next_views()
        imgui.begin_disabled(bool(running or refining))
        imgui.begin_disabled(not next_views)
        if imgui.button(f"Run update {state.viewing_update + 1}"):
            actions.run_update()
        imgui.end_disabled()
        app.note_widget("run_update")
        if imgui.is_item_hovered(imgui.HoveredFlags_.allow_when_disabled | imgui.HoveredFlags_.for_tooltip):
            imgui.set_tooltip(self._update_tip(bool(running or refining), next_views))
        imgui.same_line()
        if imgui.button("Refine"):
            actions.run_refine()
        app.note_widget("refine")
        if imgui.is_item_hovered(imgui.HoveredFlags_.allow_when_disabled | imgui.HoveredFlags_.for_tooltip):
            imgui.set_tooltip("Fit the field to all the views for the chosen minutes (per-scene refinement);\n"
                              "the viewport shows it improving; Cancel keeps the best state so far.")
        imgui.same_line()
        imgui.set_next_item_width(110)
        changed, minutes = imgui.slider_float("min##refine", state.choices.refine_minutes, 0.5, 10.0, "%.1f min")
        if changed:
            state.choices.refine_minutes = round(minutes * 2) / 2
            state.save_choices()
        saved_choice_checkbox(state, "refine the materials too (for relighting)", "refine_materials",
                              "Refine also inverse-renders albedo, roughness and metallic under the lighting the photos\n"
                              "were taken in, so the asset relights without the photos' shading baked in.")
        imgui.begin_disabled(not state.choices.refine_materials)
        saved_choice_checkbox(state, "also read them with the material network", "refine_material_network",
                              "With the materials: each photo's metal and paint colour as the image-space material network\n"
                              "sees them hold the fit's. It finds thin metal lines the photos alone cannot, but it knows only\n"
                              "objects like the ones it was trained on, so it is heard only when its metal holds still as the\n"
                              "photos are mirrored and their exposure moved (the refinement's notes say which). Off: never.")
        imgui.end_disabled()
        saved_choice_checkbox(state, "open what the photos see into (a cup's inside)", "refine_carve_openings",
                              "Before the fit, Refine carves the masks' outline hull where the photos see through it\n"
                              "(a mug's opening, which every silhouette covers) and continues the inside down to a floor.\n"
                              "Turn it off if it opens a solid object (lirm refine --no-carve-openings).")
        imgui.end_disabled()
        saved_choice_checkbox(state, "updates automatically as views arrive", "auto_update")
        imgui.text_wrapped(f"views for it: {', '.join(next_views) or 'none left: every view is used'}")
        for job in running + refining + app.jobs.running("preview"):
            job_progress(job, app.jobs.cancel)
        if state.weights:
            coloured(f"weights: {state.weights}", "info" if "UNTRAINED" not in state.weights.upper() else "warning")
        imgui.separator()
        imgui.text_wrapped("History (click to step back; the next update goes on from there):")
        if imgui.selectable("0: nothing yet", state.viewing_update == 0)[0]:
            actions.step_back(0)
        for u in state.updates:
            cost = state.update_costs.get(u["update"])
            extra = f"; job {cost[0]:.1f} s, {cost[1]:.0f} MB peak" if cost and cost[1] else ""
            if u.get("kind") == "refine":
                label = f"{u['update']}: refined, {len(u['frames'])} views, {u.get('seconds', 0):.0f} s"
                full = (f"Step {u['update']}: refined from {u.get('started_from', '?')} on {len(u['frames'])} views, "
                        f"{u.get('steps', 0)} steps in {u.get('seconds', 0):.0f} s{extra}")
            else:
                network = format_seconds(u.get("seconds", 0))
                label = f"{u['update']}: {len(u['frames'])} views, network {network}"
                full = f"Update {u['update']}: {len(u['frames'])} views, network {network}{extra}"
            full += "\nviews: " + ", ".join(self._view_names(u["frames"]))
            full += "\n(click to look at it; the next update goes on from here)"
            # The row keeps to one short line; everything about the step is in its tooltip.
            if imgui.selectable(f"{label}##history_{u['update']}", state.viewing_update == u["update"])[0]:
                actions.step_back(u["update"])
            app.note_widget(f"history_{u['update']}")
            if imgui.is_item_hovered(imgui.HoveredFlags_.for_tooltip):
                self._wrapped_tooltip(full)

    def _view_names(self, frames: list[str]) -> list[str]:
        names = {f.frame_id: f.name for f in self.app.state.frames}
        return [f"{names[f]} ({f})" if f in names and names[f] != f else f for f in frames]

    @staticmethod
    def _wrapped_tooltip(text: str) -> None:
        if imgui.begin_tooltip():
            imgui.push_text_wrap_pos(imgui.get_font_size() * 32)
            imgui.text_unformatted(text)
            imgui.pop_text_wrap_pos()
            imgui.end_tooltip()

    def _update_tip(self, busy: bool, next_views: list[str]) -> str:
        if busy:
            return "An update or refinement is running: wait for it (or cancel it) first."
        if not next_views:
            return ("Every view has been used by an update: import more photos (Capture), or step back in the\n"
                    "History below to go on from an earlier update.")
        return f"Run a LIRM update on {len(next_views)} views: " + ", ".join(self._view_names(next_views))
