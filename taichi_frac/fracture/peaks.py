"""Why a breakable body did not break: the largest principal stress its impacts caused,
against its strength, where and when, and what would have broken it.

The fracture stage hands every breakable scene body's touches and analyses to a
:class:`PeakTracker` (generation 0 only: the bodies the artist placed); after the run,
:func:`diagnose` says for each body that never broke either that no touch reached its
force threshold, or its peak stress with the impact that caused it and two estimates:

- **strength**: the body breaks where the peak exceeds its tensile strength (the Rankine
  test of ``cracks.analyze_impact``), so any strength below the peak breaks it at the same
  impact (exact for this impact; a weaker body may also crack earlier, on a lighter touch);
- **speed**: every stress model is linear elasticity under the contact force at a fixed
  load-patch radius (the particle radius, or ``FractureOptions.contact_radius``), so the
  stress is proportional to the force. An impact's force is the Hertz peak
  (``dynamics/impacts.py``): F ∝ v^(6/5) at fixed masses, radii and moduli (Johnson, Contact
  Mechanics, 1985, eq. 11.24: δ ∝ v^(4/5), F ∝ δ^(3/2)). Hence σ ∝ v^(6/5), and the approach
  speed that brings the peak to the strength is v (strength / peak)^(5/6). It holds for the
  same geometry of contact (the same orientation and point on the body); a faster body that
  lands another way, or a second impact, can change it. A sustained contact's force is its
  impulse over the substep (resting, sliding, pushing), which speed does not set: no speed
  estimate is given for it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..kinematics.quaternion import quaternion_matrix

# sigma ∝ v^(6/5) (see the module docstring): the speed to break is v (strength/peak)^(5/6).
SPEED_EXPONENT = 5.0 / 6.0


@dataclass
class BodyPeak:
    """The most stressed analysed impact of one scene body so far, and its largest touch.

    Attributes:
        name: the scene object's name.
        strength: [Pa] its tensile strength.
        force_threshold: [N] its fracture.impact_force_threshold.
        largest_force: [N] the largest contact force of any of its touches (analysed or not).
        analyses: how many of its touches were analysed (over the threshold).
        peak_stress: [Pa] the largest principal stress of those analyses (0: none).
        frame: the output frame of that analysis (None: none).
        time_in_frame: [s] the end of its substep, from the frame's start.
        point_body: (3,) [m] the most stressed particle, body frame (centre of mass origin,
            axes of the source mesh).
        point_world: (3,) [m] the same point in the world at the end of that frame's substep
            (the contact point plus the offset turned by the body's orientation).
        impact_point_world: (3,) [m] where the touch struck, world.
        impact_force: [N] its contact force.
        impact_speed: [m/s] its approach speed.
        hertz: whether its force is a Hertz impact's peak (False: a sustained contact).
    """

    name: str
    strength: float
    force_threshold: float
    largest_force: float = 0.0
    analyses: int = 0
    peak_stress: float = 0.0
    frame: int | None = None
    time_in_frame: float = 0.0
    point_body: np.ndarray = field(default_factory=lambda: np.zeros(3))
    point_world: np.ndarray = field(default_factory=lambda: np.zeros(3))
    impact_point_world: np.ndarray = field(default_factory=lambda: np.zeros(3))
    impact_force: float = 0.0
    impact_speed: float = 0.0
    hertz: bool = False


class PeakTracker:
    """Per scene body (generation 0, breakable): its largest touch and its most stressed
    analysis. Fed by the fracture stage; costs a few numpy reductions per analysis."""

    def __init__(self):
        self.bodies: dict[str, BodyPeak] = {}

    def _body(self, record) -> BodyPeak | None:
        if record.generation != 0 or not record.breakable:
            return None
        if record.name not in self.bodies:
            self.bodies[record.name] = BodyPeak(name=record.name, strength=float(record.material.tensile_strength),
                                                force_threshold=float(record.fracture.impact_force_threshold))
        return self.bodies[record.name]

    def touched(self, record, impacts: dict, rows: np.ndarray) -> None:
        """A body's strongest touches of a step (analysed or not)."""
        peak = self._body(record)
        if peak is None or len(rows) == 0:
            return
        peak.largest_force = max(peak.largest_force, float(np.linalg.norm(impacts["force"][rows], axis=1).max()))

    def analysed(self, record, analysis, impacts: dict, rows: np.ndarray, frame: int, orientation) -> None:
        """An analysis of ``record``'s touches ``rows``; ``orientation()``: the body's (w,x,y,z)
        now (read from the device only when this analysis is the body's new peak)."""
        peak = self._body(record)
        if peak is None:
            return
        peak.analyses += 1
        stress = analysis.particle_principal_stress
        if len(analysis.analysis_particle) == 0 or not np.any(np.isfinite(stress)):
            return
        # Each contact's analysis point is the most stressed particle within its reach; the
        # largest of them is the largest over every particle the analysis computed.
        at_points = stress[analysis.analysis_particle]
        k = int(np.nanargmax(at_points))
        value = float(at_points[k])
        if value <= peak.peak_stress:
            return
        row = int(rows[k]) if len(rows) == len(analysis.analysis_particle) else int(
            rows[np.argmax(np.linalg.norm(impacts["force"][rows], axis=1))])
        point_body = np.asarray(analysis.analysis_point[k], dtype=np.float64)
        turn = quaternion_matrix(np.asarray(orientation(), dtype=np.float64))
        peak.peak_stress = value
        peak.frame = int(frame)
        peak.time_in_frame = float((impacts["substep"][row] + 1) * impacts["dt"][row])
        peak.point_body = point_body
        peak.impact_point_world = np.asarray(impacts["point"][row], dtype=np.float64)
        peak.point_world = peak.impact_point_world + turn @ (point_body - impacts["point_body"][row])
        peak.impact_force = float(np.linalg.norm(impacts["force"][row]))
        peak.impact_speed = float(impacts["speed"][row])
        peak.hertz = bool(impacts["duration"][row] > 0.0)


def diagnose(tracker: PeakTracker | None, unbroken: list[str], frame_dt: float) -> list[dict]:
    """For each scene body named in ``unbroken`` (breakable, never split): a JSON-ready dict
    with ``name``, ``note`` (one line) and, when a touch was analysed, ``peak_stress`` [Pa],
    ``strength`` [Pa], ``frame``, ``time`` [s], ``point_body`` and ``point_world`` [m],
    ``impact_point_world`` [m], ``impact_force`` [N], ``impact_speed`` [m/s],
    ``break_speed`` [m/s] (None for a sustained contact) and ``break_strength`` [Pa] (the
    peak: any strength below it breaks the body at that impact)."""
    out = []
    for name in unbroken:
        peak = None if tracker is None else tracker.bodies.get(name)
        if peak is None or peak.largest_force == 0.0:
            out.append({"name": name, "note": "it touched nothing (no contact with the ground or another body)"})
            continue
        if peak.frame is None:
            out.append({"name": name, "largest_force": peak.largest_force, "force_threshold": peak.force_threshold,
                        "note": f"no touch reached its force threshold: largest {peak.largest_force:.4g} N < "
                                f"impact_force_threshold {peak.force_threshold:.4g} N; lower the threshold"})
            continue
        ratio = peak.strength / peak.peak_stress if peak.peak_stress > 0.0 else float("inf")
        speed = peak.impact_speed * ratio ** SPEED_EXPONENT if peak.hertz and np.isfinite(ratio) else None
        entry = {
            "name": name, "peak_stress": peak.peak_stress, "strength": peak.strength, "frame": peak.frame,
            "time": (peak.frame - 1) * frame_dt + peak.time_in_frame,
            "point_body": peak.point_body.tolist(), "point_world": peak.point_world.tolist(),
            "impact_point_world": peak.impact_point_world.tolist(), "impact_force": peak.impact_force,
            "impact_speed": peak.impact_speed, "break_speed": speed, "break_strength": peak.peak_stress,
            "analyses": peak.analyses,
        }
        if peak.peak_stress >= peak.strength:
            note = (f"peak stress {peak.peak_stress / 1e6:.3g} MPa reached its strength "
                    f"{peak.strength / 1e6:.3g} MPa at frame {peak.frame}, but its cracks cut off no piece: "
                    "lengthen the cracks (crack_length) or lower min_fragment_particles")
        else:
            note = (f"peak stress {peak.peak_stress / 1e6:.3g} MPa < strength {peak.strength / 1e6:.3g} MPa "
                    f"at frame {peak.frame} (impact at {peak.impact_speed:.3g} m/s); ")
            note += (f"breaks at about {speed:.3g} m/s impact speed, or with a strength below "
                     f"{peak.peak_stress / 1e6:.3g} MPa" if speed is not None else
                     f"a sustained contact (speed does not set its force): breaks with a strength below "
                     f"{peak.peak_stress / 1e6:.3g} MPa")
        entry["note"] = note
        out.append(entry)
    return out
