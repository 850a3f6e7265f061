"""Part 4: stability, the hard cases of the dynamics and of the fracture.

Each case is set up as the tests set it up (the bodies come from the set-up modules the
tests share with the report, ``bodies`` and ``fracture_ring``, the one-tet isolation
included) and then simulated on the report's World,
sampling every frame end: the largest body speed, the deepest collision sphere inside the
ground or a static box, and any NaN. A fracture case analyses the impact, splits the ring
and drops every resulting piece onto the ground for a second, so its row says whether the
pieces it makes are safe to simulate.

Criteria (all must hold for "pass"): no NaN anywhere (state, stress, fragment data); speed
never above what energy allows (sqrt(v0^2 + 2 g h) over the case's starting speeds and
heights) plus the split impulse's capped push-out speed ``max_correction_speed``;
penetration below one collision radius of the body (the scene tests' bound); plus the
case's own check (named in its row).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from taichi_frac.kinematics.quaternion import quaternion_matrix
from tests.support import fracture_ring as ring
from tests.support.bodies import box_model, single_tet_model, sphere_model
from .common import BenchContext, Section, md_table

G = 9.81


class Tracker:
    """Samples a World's bodies at frame ends: max speed, max penetration into the ground
    planes and static boxes given, NaN. Collision spheres are read once (they are fixed in
    the body frame) and posed with numpy for every body at once."""

    def __init__(self, world, grounds=(0.0,), boxes=()):
        self.world = world
        self.grounds = list(grounds)
        self.boxes = [(np.asarray(c, float), np.asarray(h, float), quaternion_matrix(np.asarray([q], float))[0])
                      for c, h, q in boxes]
        self.max_speed = 0.0
        self.max_penetration = 0.0
        self.max_penetration_ratio = 0.0
        self.nan = False
        self.refresh()
        self.sample()  # the starting state counts (a fast body may have bounced by the first frame end)

    def refresh(self):
        """Re-read the bodies (after fragments were added)."""
        offsets = self.world.particles.offset.to_numpy().astype(np.float64)
        radii = self.world.particles.radius.to_numpy().astype(np.float64)
        self.ids = np.array(self.world.body_ids)
        index, self.owner = [], []
        for k, b in enumerate(self.ids):
            start, count = self.world.slots.body_range[int(b)]
            index.append(np.arange(start, start + count))
            self.owner.append(np.full(count, k))
        index = np.concatenate(index)
        self.owner = np.concatenate(self.owner)
        self.offsets, self.radii = offsets[index], radii[index]

    def sample(self) -> dict:
        state = self.world.body_state(self.ids)
        finite = all(np.all(np.isfinite(state[k])) for k in ("position", "orientation", "linear_velocity",
                                                             "angular_velocity"))
        if not finite:
            self.nan = True
            return state
        self.max_speed = max(self.max_speed, float(np.linalg.norm(state["linear_velocity"], axis=1).max()))
        rot = quaternion_matrix(state["orientation"])[self.owner]
        p = state["position"][self.owner] + np.einsum("kij,kj->ki", rot, self.offsets)
        depth = np.zeros(len(p))
        for h in self.grounds:
            depth = np.maximum(depth, self.radii - (p[:, 2] - h))
        for centre, half, r in self.boxes:
            local = np.abs((p - centre) @ r) - half
            outside = np.linalg.norm(np.maximum(local, 0.0), axis=1) + np.minimum(local.max(axis=1), 0.0)
            depth = np.maximum(depth, self.radii - outside)
        self.max_penetration = max(self.max_penetration, float(depth.max()))
        self.max_penetration_ratio = max(self.max_penetration_ratio, float((depth / self.radii).max()))
        return state

    def run(self, frames: int, frame_dt: float = 0.02, substeps: int = 10, each=None):
        for _ in range(frames):
            self.world.advance(frame_dt, substeps)
            state = self.sample()
            if self.nan:
                return
            if each is not None:
                each(state)


@dataclass
class CaseResult:
    case: str
    kind: str  # "dynamics" or "fracture": the part of the simulation the case stresses
    criterion: str
    passed: bool
    max_speed: float
    speed_bound: float
    max_penetration: float
    penetration_ratio: float
    nan: bool
    notes: str = ""
    extra: dict = field(default_factory=dict)


def _world(ctx, **options):
    from taichi_frac.dynamics import DynamicsOptions

    world = ctx.world()
    world.clear()
    world.set_options(DynamicsOptions(**options))
    return world


def _result(name, kind, own_check, own_ok, tracker, bound, notes="", extra_nan=False):
    ok_speed = tracker.max_speed <= bound
    ok_pen = tracker.max_penetration_ratio < 1.0
    nan = tracker.nan or extra_nan
    passed = (not nan) and ok_speed and ok_pen and own_ok
    criterion = f"no NaN; speed <= {bound:.2f} m/s; penetration < 1 radius" + (f"; {own_check}" if own_check else "")
    return CaseResult(name, kind, criterion, passed, tracker.max_speed, bound, tracker.max_penetration,
                      tracker.max_penetration_ratio, nan, notes)


def _bound(world, speeds_heights):
    """Energy bound on speed: max over bodies of sqrt(v0^2 + 2 g h) + the push-out cap."""
    return max(math.sqrt(v * v + 2 * G * max(h, 0.0)) for v, h in speeds_heights) + world.options.max_correction_speed


# ------------------------------------------------------------------ dynamics

def case_deep_overlap(ctx, frames=100):
    world = _world(ctx)
    world.add_ground(0.0)
    sphere = sphere_model(0.05)
    a = world.add_body(sphere, (1.0, 0, 0.3))
    b = world.add_body(sphere, (1.01, 0, 0.3))
    t = Tracker(world)
    t.run(frames)
    state = world.body_state([a, b])
    gap = float(np.linalg.norm(state["position"][0] - state["position"][1]))
    return _result("bodies starting deeply overlapped (two 5 cm spheres, centres 1 cm apart)", "dynamics",
                   "separated to >= 1.5 radii", gap >= 0.075, t, _bound(world, [(0, 0.3)]),
                   f"centre distance at the end {100 * gap:.1f} cm")


def case_mass_ratio(ctx, frames=100):
    world = _world(ctx)
    world.add_ground(0.0)
    small, big = box_model(0.02, 0.02, 0.02, pieces=30, density=2400.0), box_model(0.2, 0.2, 0.2, pieces=300)
    b = world.add_body(big, (0, 0, 0.11))
    a = world.add_body(small, (0, 0, 0.24))
    t = Tracker(world)
    t.run(frames)
    state = world.body_state([a, b])
    z = state["position"][:, 2]
    rot = quaternion_matrix(state["orientation"][1])
    local = (state["position"][0] - state["position"][1]) @ rot  # small cube in the big one's frame
    # The boxes are coarsely meshed (their boundary layers are a few large spheres), so the
    # small cube may roll off the big one's rounded top: the criterion is that it never
    # sinks into the big one (centre outside the 20 cm box less its own half size).
    outside = bool(np.max(np.abs(local)) >= 0.1 - 0.01)
    ratio = big.mass / small.mass
    return _result(f"mass ratio 1:{ratio:.0f} (2 cm cube dropped on a 20 cm cube)", "dynamics",
                   "small cube never inside the big one", outside, t, _bound(world, [(0, 0.24)]),
                   f"heights small / big {z[0]:.3f} / {z[1]:.3f} m, small in big's frame "
                   f"{np.round(local, 3).tolist()} m")


def case_single_tet(ctx, frames=100):
    world = _world(ctx)
    world.add_ground(0.0)
    tet = single_tet_model()
    body = world.add_body(tet, (0, 0, 0.2), (0.9, 0.3, 0.2, 0.1))
    t = Tracker(world)
    t.run(frames)
    z = float(world.body_state([body])["position"][0][2])
    return _result("a body of a single tet (5 cm edges)", "dynamics", "above the ground at the end", z > 0.0, t,
                   _bound(world, [(0, 0.2)]), f"COM height at the end {1e3 * z:.1f} mm")


def case_pile(ctx, frames=25, bodies=1000):
    world = _world(ctx)
    world.add_ground(0.0)
    boxes = []
    for sign in (-1, 1):
        for c, h in (((sign * 0.3, 0, 0.3), (0.02, 0.32, 0.3)), ((0, sign * 0.3, 0.3), (0.32, 0.02, 0.3))):
            world.add_static_box(c, h)
            boxes.append((c, h, (1, 0, 0, 0)))
    tet = single_tet_model(0.04)
    side = round(bodies ** (1 / 3))
    grid = np.stack(np.meshgrid(*(np.arange(side) * 0.05 - 0.025 * (side - 1),) * 2, np.arange(side) * 0.05 + 0.1,
                                indexing="ij"), -1).reshape(-1, 3)
    for p in grid:
        world.add_body(tet, p, (1, 0, 0, 0), (0, 0, 0), (1.0, 2.0, 3.0))
    t = Tracker(world, boxes=boxes)
    t.run(frames, substeps=4)
    inside = bool(np.all(np.abs(world.body_state()["position"][:, :2]) < 0.3))
    overflows = world.stats.contact_overflows
    spin = 3.0 * 0.04  # |w| x edge: the bodies start spinning
    return _result(f"{len(grid):,} single-tet bodies in a pile (walls, {frames} frames)", "dynamics",
                   "no contact lost to capacity; all inside the walls", inside and overflows == 0, t,
                   _bound(world, [(spin, float(grid[:, 2].max()))]), f"contacts lost {overflows}")


def case_fast_sphere(ctx):
    world = _world(ctx, max_substeps=5000)
    model = sphere_model(0.01, subdivisions=1, pieces=20)
    half = (0.01, 0.2, 0.2)
    world.add_static_box((0.1, 0, 0), half, friction=0.2, restitution=0.2)
    body = world.add_body(model, (0, 0, 0), (1, 0, 0, 0), (100.0, 0, 0), (0, 0, 0))
    t = Tracker(world, grounds=(), boxes=[((0.1, 0, 0), half, (1, 0, 0, 0))])
    xs = []
    t.run(4, frame_dt=0.005, substeps=1, each=lambda st: xs.append(float(st["position"][0][0])))
    vx = float(world.body_state([body])["linear_velocity"][0][0])
    ok = bool(xs) and max(xs) < 0.09 + 1e-3 and vx < 0
    return _result("a 1 cm sphere at 100 m/s against a 2 cm wall", "dynamics", "never past the wall's face; bounced back",
                   ok, t, _bound(world, [(100.0, 0.0)]),
                   f"furthest x {max(xs) if xs else float('nan'):.4f} m (wall face 0.09 m), vx at the end {vx:.1f} m/s, "
                   f"{world.stats.total_substeps} substeps")


# ------------------------------------------------------------------ fracture

def _ring_material(poisson_ratio=0.2):
    from taichi_frac.options import Material

    return Material(name="ring", density=2400.0, young_modulus=70e9, poisson_ratio=poisson_ratio,
                    tensile_strength=1.0e6)


def _drop_pieces(ctx, pieces_or_models, frames):
    """Put fragments (FragmentPiece list) on a ground and simulate; returns the Tracker."""
    world = _world(ctx)
    world.add_ground(0.0)
    for piece in pieces_or_models:
        world.add_body(piece.model, piece.position, piece.orientation, piece.linear_velocity,
                       piece.angular_velocity)
    t = Tracker(world)
    t.run(frames)
    return t, world


def _fracture_case(ctx, name, model, points, normals, forces, material, options, frames, own_check=None,
                   pose_height=0.3, parent_generation=0):
    from taichi_frac.fracture.cracks import analyze_impact
    from taichi_frac.fracture.fragments import make_fragments, split_body
    from taichi_frac.options import ParticleOptions

    analysis = analyze_impact(model, points, normals, forces, material, options)
    stress_nan = not (np.all(np.isfinite(analysis.particle_stress)) and np.all(np.isfinite(analysis.particle_principal_stress)))
    split = split_body(model, analysis, options)
    pose = dict(position=np.array([0.0, 0.0, pose_height]), orientation_wxyz=np.array([1.0, 0.0, 0.0, 0.0]),
                linear_velocity=np.zeros(3), angular_velocity=np.array([0.0, 0.0, 1.0]))
    pieces = make_fragments(model, split, **pose, material=material, particle_options=ParticleOptions(),
                            options=options, analysis=analysis, parent_generation=parent_generation)
    piece_nan = any(not (np.all(np.isfinite(p.model.inertia)) and np.all(np.isfinite(p.position))) for p in pieces)
    mass = sum(p.model.mass for p in pieces) + split.dropped_mass
    mass_ok = abs(mass - model.mass) <= 1e-9 * model.mass
    t, world = _drop_pieces(ctx, pieces, frames)
    own_ok, own_text = (True, "") if own_check is None else own_check(analysis, split, pieces)
    spin = 1.0 * 0.125  # |w| x ring radius
    result = _result(name, "fracture", "mass conserved by the split" + (f"; {own_text}" if own_text else ""),
                     own_ok and mass_ok, t, _bound(world, [(spin, pose_height)]),
                     f"peak principal stress {analysis.peak_principal_stress / 1e6:.3g} MPa, "
                     f"{len(analysis.cracks)} cracks, {len(pieces)} pieces", extra_nan=stress_nan or piece_nan)
    result.extra = dict(pieces=pieces, analysis=analysis)
    return result


def fracture_cases(ctx, frames=50, model=None):
    """The fracture's hard cases on ``model`` (default: the fracture tests' ~5,000-tet ring)."""
    from taichi_frac.fracture.cracks import analyze_impact
    from taichi_frac.fracture.fragments import split_body
    from taichi_frac.options import FractureOptions

    model = model if model is not None else ring.struck_ring_model()
    contact, normal, force = ring.RING_CONTACT, ring.RING_NORMAL, ring.RING_FORCE
    unit = normal
    material = _ring_material()
    opts = FractureOptions(crack_count=2, crack_length=0.3, seed=0)
    out = []
    on_particle = model.particle_position[int(np.argmin(np.linalg.norm(model.particle_position - contact, axis=1)))]
    out.append(_fracture_case(ctx, "contact exactly on a particle (1e4 N)", model, on_particle, normal, force,
                              material, opts, frames))
    out.append(_fracture_case(ctx, "a 1e9 N contact", model, contact, normal, 1e9 * unit, material, opts, frames))

    def linear(analysis, split, pieces):
        ref = analyze_impact(model, contact, normal, 1.0 * unit, material, opts)
        ratio = np.linalg.norm(analysis.particle_stress - 1e-6 * ref.particle_stress) / max(
            np.linalg.norm(1e-6 * ref.particle_stress), 1e-300)
        return (not analysis.any_crack and ratio < 1e-6), f"no crack; stress = 1e-6 x the 1 N stress (rel. {ratio:.0e})"

    out.append(_fracture_case(ctx, "a 1e-6 N contact", model, contact, normal, 1e-6 * unit, material,
                              FractureOptions(crack_count=2, crack_length=0.3, seed=0, impact_force_threshold=0.0),
                              frames, own_check=linear))
    for nu in (0.0, 0.49):
        out.append(_fracture_case(ctx, f"Poisson ratio {nu:g} (1e4 N)", model, contact, normal, force,
                                  _ring_material(nu), opts, frames))
    tet = int(model.surface_particles[0])
    one_opts = FractureOptions(min_fragment_particles=1)
    split = split_body(model, ring.corner_cracks(model, tet), one_opts)
    from taichi_frac.fracture.fragments import make_fragments
    from taichi_frac.options import ParticleOptions

    pieces = make_fragments(model, split, np.array([0, 0, 0.3]), np.array([1.0, 0, 0, 0]), np.zeros(3),
                            np.array([0, 0, 1.0]), material, ParticleOptions(), options=one_opts)
    single = [p for p in pieces if p.model.tet_count == 1]
    t, world = _drop_pieces(ctx, pieces, frames)
    nan = any(not np.all(np.isfinite(p.model.inertia)) for p in pieces)
    out.append(_result("a one-tet fragment (isolated by cracks on its faces), dropped with the ring", "fracture",
                       "a 1-tet piece exists, positive inertia",
                       bool(single) and all(np.all(np.linalg.eigvalsh(p.model.inertia) > 0) for p in single),
                       t, _bound(world, [(0.125, 0.3)]), f"{len(pieces)} pieces, {len(single)} of one tet",
                       extra_nan=nan))
    second = -contact
    out.append(_fracture_case(ctx, "a body hit at two points in one step (1e4 N each)", model,
                              np.stack([contact, second]), np.stack([normal, -normal]), np.stack([force, -force]),
                              material, FractureOptions(crack_count=2, crack_length=0.05), frames,
                              own_check=lambda a, s, p: ({c.impact_index for c in a.cracks} == {0, 1},
                                                         "cracks from both contacts")))
    first = out[0].extra["pieces"]
    piece = max(first, key=lambda f: f.model.tet_count)
    x = piece.model.particle_position
    far = x[np.argmax(np.linalg.norm(x, axis=1))]
    n_far = -far / np.linalg.norm(far)
    out.append(_fracture_case(ctx, "a fragment hit again (largest piece of the first case, 1e4 N)", piece.model,
                              far, n_far, 1e4 * n_far, material, FractureOptions(crack_count=2, crack_length=0.3,
                                                                                 seed=1), frames,
                              parent_generation=piece.generation,
                              own_check=lambda a, s, p: (all(f.generation == piece.generation + 1 for f in p),
                                                         "pieces are one generation deeper")))
    return out


def run(ctx: BenchContext, quick_frames: int = 15) -> Section:
    t0 = time.perf_counter()
    frames = quick_frames if ctx.quick else 100
    cases = []
    for fn, kwargs in ((case_deep_overlap, dict(frames=frames)), (case_mass_ratio, dict(frames=frames)),
                       (case_single_tet, dict(frames=frames)),
                       (case_pile, dict(frames=min(frames, 25), bodies=125 if ctx.quick else 1000)),
                       (case_fast_sphere, {})):
        cases.append(fn(ctx, **kwargs))
        ctx.progress(f"stability: {cases[-1].case}: {'pass' if cases[-1].passed else 'FAIL'}")
    for c in fracture_cases(ctx, frames=min(frames, 50)):
        cases.append(c)
        ctx.progress(f"stability: {c.case}: {'pass' if c.passed else 'FAIL'}")
    return section(cases, time.perf_counter() - t0, frames)


def section(cases: list[CaseResult], seconds: float, frames: int) -> Section:
    rows = [[f"{c.case} ({c.kind})", ("pass" if c.passed else "**FAIL**") + f": {c.criterion}",
             f"{c.max_speed:.2f}", f"{1e3 * c.max_penetration:.2f} ({c.penetration_ratio:.2f} r)",
             "found" if c.nan else "none", c.notes] for c in cases]
    passed = sum(c.passed for c in cases)
    text = "\n".join([
        "The hard cases of the dynamics and the fracture, set up as the tests set them up, simulated and "
        f"sampled at every frame end ({frames} frames of 20 ms unless the case says otherwise; fracture cases: "
        "the impact is analysed, the ring split and every piece dropped from 0.3 m onto the ground). Max "
        "penetration: the deepest collision sphere inside the ground or a static box, in mm and in units of "
        "that sphere's radius r. The speed bound is sqrt(v0^2 + 2 g h) plus the split impulse's push-out cap.",
        "",
        md_table(["case", "result (criterion)", "max speed [m/s]", "max penetration [mm]", "NaN", "measured"], rows,
                 "llrrcl"),
        "",
        f"**{passed} of {len(cases)} cases pass.** *Part time: {seconds:.0f} s.*",
    ])
    return Section("stability", "Stability: the hard cases", text, [], dict(passed=passed, total=len(cases),
                                                                          cases=cases))
