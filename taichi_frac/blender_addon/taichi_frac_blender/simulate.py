"""Simulate from Blender: export the authored scene, run ``taichi-frac run`` in its own
process, import its cache back (or update it in place) and hide the authored breakable and
rigid objects while the cache shows them (their pieces, or themselves moving).

``bpy.ops.taichi_frac.simulate()`` from the panel is modal: the status bar shows the frame
and the pieces so far, Esc stops the run (the command keeps a valid cache of the frames
done, which is imported). ``wait=True`` blocks until the run ends (scripts, tests, and
Blender without a window). A run that fails reports the command's one-line error.

What the run found about each breakable body (it broke, or why it did not: its peak stress
against its strength, where and when, and the impact speed that would break it) comes from
the run's stats file and is kept on ``Object.taichi_frac_sim.result_*``.
"""

from __future__ import annotations

import json
import os
import time
import traceback

import bpy
from bpy.props import BoolProperty

from . import export, runner

# How often the modal operator reads the child's progress [s].
POLL_SECONDS = 0.2


def _modified(path: str):
    """The file's modification time [ns], or None when there is no file."""
    try:
        return os.stat(path).st_mtime_ns
    except OSError:
        return None


def executable_preference(context) -> str:
    addon = context.preferences.addons.get(__package__)
    return addon.preferences.executable if addon is not None and addon.preferences is not None else ""


class Job:
    """One simulation from export to import: :meth:`start` exports and starts the command,
    :meth:`finish` (after the run ended) imports the cache and records the results."""

    def __init__(self, context):
        self.scene = context.scene
        self.exported: export.Export | None = None
        self.run: runner.SimulationRun | None = None
        self.started = 0.0
        self.shown = []  # objects hidden by the last simulation, shown to be exported
        self.cache_before = None  # the cache file's modification time before the run

    def hide_again(self) -> None:
        """After a failure: hide again what the last simulation had hidden (its pieces still show)."""
        for obj in self.shown:
            obj.hide_viewport = obj.hide_render = True
            obj.taichi_frac_sim.hidden_by_simulation = True

    def start(self, context) -> None:
        """Raises runner.RunError or export.ExportError (one line each)."""
        executable, _ = runner.find_executable(executable_preference(context))
        self.shown = [o for o in self.scene.objects if o.taichi_frac_sim.hidden_by_simulation]
        for obj in self.shown:  # (a hidden object is not evaluated: show it to read its mesh)
            obj.hide_viewport = False
            obj.hide_render = False
            obj.taichi_frac_sim.hidden_by_simulation = False
        try:
            self.exported = export.export_scene(context)
        except Exception:
            self.hide_again()
            raise
        if os.path.exists(self.exported.stats_path):
            os.remove(self.exported.stats_path)  # (a failed run must not show the last run's findings)
        # A run stopped before its first frame writes no cache: the last run's must not be
        # taken for it.
        self.cache_before = _modified(self.exported.cache_path)
        self.run = runner.SimulationRun(executable, self.exported.scene_path, self.exported.stats_path)
        self.started = time.perf_counter()
        self.run.start()

    def status_text(self) -> str:
        p = self.run.progress
        if self.run.cancelled:
            return f"taichi-frac: stopping after frame {p.frame}, keeping the frames done ..."
        if not p.frames:
            return f"taichi-frac: preparing the bodies ({time.perf_counter() - self.started:.0f} s) - Esc to stop"
        if p.surfaces_left >= 0:
            return (f"taichi-frac: frames done, cutting the pieces' surfaces: {p.surfaces_left} of "
                    f"{p.surfaces_splits} splits left - Esc to stop and keep what is done")
        return (f"taichi-frac: frame {p.frame}/{p.frames}, {p.fragments} pieces, {p.fps:.1f} frames/s"
                " - Esc to stop and keep the frames done")

    def finish(self, context) -> tuple[str, str]:
        """After the run ended: (report level, one-line message); imports the cache when the
        run wrote one (finished, or stopped with the frames done)."""
        code = self.run.poll()
        written = _modified(self.exported.cache_path) not in (None, self.cache_before)
        if self.run.cancelled and not written:  # (stopped while Python was still starting: any status)
            self.hide_again()
            return "WARNING", "taichi-frac: the run was stopped before its first frame: nothing to import"
        if code not in (0, 130) or not written:
            self.hide_again()
            return "ERROR", f"taichi-frac: the run failed: {self.run.error_line()}"
        from . import run_import  # (the package's import function; imported late: no cycle at load)

        with context.temp_override(scene=self.scene):  # (the scene simulated, whichever shows now)
            result = run_import(bpy.context, self.exported.cache_path, set_scene_settings=False,
                                frame_offset=float(self.exported.frame_start), update_existing=True)
        self._hide_authored()
        findings = self._record_findings()
        frames = self.run.progress.frame
        what = "stopped, frames done imported" if code == 130 else "done"
        message = (f"taichi-frac: simulation {what}: {frames} frames, {result.created} new and {result.updated} "
                   f"updated pieces in {time.perf_counter() - self.started:.1f} s")
        if findings:
            message += "; " + findings
        self.scene.taichi_frac_sim.last_message = message
        return ("WARNING" if result.warnings and code != 130 else "INFO"), message

    def _hide_authored(self) -> None:
        """Hide the authored bodies: the cache holds each of them (its pieces, or the body
        itself moving), which shows instead. Static colliders stay."""
        for name in self.exported.names.values():
            obj = self.scene.objects.get(name)
            if obj is not None and obj.taichi_frac_sim.role in ("BREAKABLE", "RIGID"):
                obj.hide_viewport = True
                obj.hide_render = True
                obj.taichi_frac_sim.hidden_by_simulation = True

    def _record_findings(self) -> str:
        """Each breakable object's result from the stats file; a one-line summary of those
        that did not break."""
        try:
            with open(self.exported.stats_path, encoding="utf-8") as f:
                stats = json.load(f)
        except (OSError, ValueError):
            return ""
        unbroken = {entry["name"]: entry for entry in stats.get("unbroken", [])}
        notes = []
        for scene_name, blender_name in self.exported.names.items():
            obj = self.scene.objects.get(blender_name)
            if obj is None or blender_name not in self.exported.breakable:
                continue
            props = obj.taichi_frac_sim
            entry = unbroken.get(scene_name)
            if entry is None:
                props.result_state = "BROKE"
                props.result_note = ""
                continue
            props.result_state = "UNBROKEN"
            props.result_peak_stress = entry.get("peak_stress") or 0.0
            props.result_strength = entry.get("strength") or 0.0
            frame = entry.get("frame")
            props.result_frame = -1.0 if frame is None else self.exported.frame_start + frame
            point = entry.get("point_world")
            props.result_point = point if point else (0.0, 0.0, 0.0)
            props.result_impact_speed = entry.get("impact_speed") or 0.0
            props.result_break_speed = entry.get("break_speed") or 0.0
            props.result_note = entry.get("note", "")
            notes.append(f"{blender_name} did not break ({props.result_note})")
        return "; ".join(notes)


class TAICHI_FRAC_OT_simulate(bpy.types.Operator):
    """Simulate the objects with a taichi-frac role in a separate taichi-frac process and
    import the pieces (Esc stops and keeps the frames done)"""

    bl_idname = "taichi_frac.simulate"
    bl_label = "Simulate"
    bl_options = {"REGISTER"}

    wait: BoolProperty(name="Wait", default=False, options={"SKIP_SAVE"},
                       description="Block until the run ends (for scripts)")

    _job = None  # (the Job of a modal run)
    _timer = None

    def invoke(self, context, event):
        return self.execute(context)

    def execute(self, context):
        job = Job(context)
        try:
            job.start(context)
        except (runner.RunError, export.ExportError, OSError) as exc:
            job.hide_again()
            self.report({"ERROR"}, f"taichi-frac: {exc}")
            return {"CANCELLED"}
        if self.wait or bpy.app.background or context.window is None:
            job.run.wait()
            return self._finish(context, job)
        self._job = job
        wm = context.window_manager
        self._timer = wm.event_timer_add(POLL_SECONDS, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, 1000)
        context.workspace.status_text_set(job.status_text())
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.run.cancel()
            context.workspace.status_text_set(job.status_text())
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if job.run.poll() is None:
            context.workspace.status_text_set(job.status_text())
            context.window_manager.progress_update(int(1000 * job.run.progress.fraction))
            return {"RUNNING_MODAL"}
        self._end_modal(context)
        return self._finish(context, job)

    def cancel(self, context):  # (Blender ends the operator: the window closes, a file loads)
        if self._job is not None:
            self._job.run.kill()
        self._end_modal(context)

    def _end_modal(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)

    def _finish(self, context, job: Job):
        try:
            level, message = job.finish(context)
        except (OSError, ImportError, ValueError) as exc:  # (the import's CacheError is a ValueError)
            level, message = "ERROR", f"taichi-frac: the run's cache {job.exported.cache_path} could not be imported: {exc}"
        except Exception as exc:  # a bug of ours: one line here, the details in the console
            traceback.print_exc()
            level, message = "ERROR", (f"taichi-frac: importing the run's cache failed ({type(exc).__name__}: {exc}); "
                                       "details in the system console")
        context.scene.taichi_frac_sim.last_message = message
        self.report({level}, message)
        return {"CANCELLED"} if level == "ERROR" else {"FINISHED"}


class TaichiFracPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    executable: bpy.props.StringProperty(
        name="taichi-frac Command", subtype="FILE_PATH", default="",
        description="The taichi-frac executable (e.g. /path/to/.venv/bin/taichi-frac); empty: the "
                    f"{runner.EXECUTABLE_ENV} environment variable, else the PATH")

    def draw(self, context):
        self.layout.prop(self, "executable")
        try:
            path, where = runner.find_executable(self.executable)
            self.layout.label(text=f"Using {path} (from {where})", icon="CHECKMARK")
        except runner.RunError as exc:
            self.layout.label(text=str(exc), icon="ERROR")


classes = (TaichiFracPreferences, TAICHI_FRAC_OT_simulate)


register, unregister = bpy.utils.register_classes_factory(classes)
