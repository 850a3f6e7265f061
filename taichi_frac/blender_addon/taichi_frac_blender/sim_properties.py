"""What the artist authors for a simulation: ``Object.taichi_frac_sim`` (role, material,
fracture controls, initial velocity) and ``Scene.taichi_frac_sim`` (ground, resolution,
substeps, cache path), and what the last run found out about each body (``result_*``).
Every number is in SI units in Blender's Z-up world; lengths are scene units times the
scene's unit scale. Each property maps onto one key of the scene file that ``export``
writes (docs/reference/scene-file.md)."""

from __future__ import annotations

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, PointerProperty,
                       StringProperty)

ROLES = (
    ("NONE", "None", "Not part of the simulation"),
    ("BREAKABLE", "Breakable", "A solid that cracks where impacts stress it beyond its strength"),
    ("RIGID", "Rigid", "A solid that moves and collides but never breaks (a projectile, a prop)"),
    ("STATIC", "Static", "A fixed collider: the engine collides with its bounding box (oriented with the object)"),
)

# The engine's presets (taichi_frac/options.py MATERIAL_PRESETS): density [kg/m^3], Young's
# modulus [Pa], Poisson's ratio, tensile strength [Pa]. Shown in the panel; the scene file
# names the preset, so the engine's own numbers are the ones simulated.
MATERIAL_PRESETS = {
    "porcelain": (2400.0, 70.0e9, 0.2, 35.0e6),
    "soda_lime_glass": (2500.0, 72.0e9, 0.23, 45.0e6),
    "concrete": (2400.0, 33.0e9, 0.2, 2.9e6),
}
MATERIALS = (
    ("porcelain", "Porcelain", "Glazed porcelain: 2400 kg/m^3, E 70 GPa, strength 35 MPa"),
    ("soda_lime_glass", "Soda-Lime Glass", "Annealed glass: 2500 kg/m^3, E 72 GPa, strength 45 MPa"),
    ("concrete", "Concrete", "Concrete C30/37: 2400 kg/m^3, E 33 GPa, strength 2.9 MPa"),
    ("custom", "Custom", "Your own density, stiffness and strength"),
)
LOOKS = tuple((k, k.replace("_", " ").title(), f"Render the pieces as {k}")
              for k in ("porcelain", "glass", "concrete", "plaster", "steel"))
STRESS_MODELS = (
    ("auto", "Auto", "The body's own elasticity for slender bodies (plates, rods, rings), which break by "
                     "bending; the half-space stress for compact ones (default)"),
    ("halfspace", "Half-Space", "The exact stress of the contact load on a half-space (the paper's model)"),
    ("sph", "SPH", "The paper's SPH estimate of that stress"),
    ("fem", "FEM", "Linear elasticity on the body's own tets, its shape included (slower)"),
)


class TaichiFracSimObject(bpy.types.PropertyGroup):
    """``Object.taichi_frac_sim``: the object's part in the simulation."""

    role: EnumProperty(name="Role", items=ROLES, default="NONE", description="What the object is in the simulation")
    material: EnumProperty(name="Material", items=MATERIALS, default="porcelain",
                           description="A material preset, or your own numbers")
    strength_override: FloatProperty(
        name="Strength [Pa]", min=0.0, default=0.0,
        description="Tensile strength replacing the preset's [Pa] (0: the preset's)")
    density: FloatProperty(name="Density [kg/m³]", min=1e-3, default=2400.0, description="Mass density [kg/m^3]")
    young_modulus: FloatProperty(name="Young's Modulus [Pa]", min=1.0, default=70.0e9,
                                 description="Stiffness E [Pa]")
    poisson_ratio: FloatProperty(name="Poisson's Ratio", min=0.0, max=0.499, default=0.2,
                                 description="Poisson's ratio [-]")
    tensile_strength: FloatProperty(name="Tensile Strength [Pa]", min=1.0, default=35.0e6,
                                    description="Largest principal stress it bears without cracking [Pa]")
    fracture_toughness: FloatProperty(name="Fracture Toughness [Pa m^0.5]", min=1.0, default=1.0e6,
                                      description="K_Ic: what new crack surface costs (G_c = K_Ic^2 / E); "
                                                  "sets the automatic crack count [Pa m^0.5]")
    look: EnumProperty(name="Look", items=LOOKS, default="porcelain", description="How the pieces render")
    friction: FloatProperty(name="Friction", min=0.0, max=10.0, default=0.5, description="Coulomb friction [-]")
    restitution: FloatProperty(name="Restitution", min=0.0, max=1.0, default=0.2,
                               description="Coefficient of restitution [-]")
    # Fracture controls (docs/guide/fracture-controls.md).
    crack_count_auto: BoolProperty(
        name="Auto Crack Count", default=True,
        description="Cracks per impact from the impact's energy against the material's fracture energy "
                    "(the engine's default); off: the count below")
    crack_scale: FloatProperty(name="Crack Scale", min=0.01, max=64.0, default=1.0,
                               description="Multiplies the automatic crack count (Auto Crack Count only)")
    crack_count: IntProperty(name="Cracks per Impact", min=1, max=64, default=3,
                             description="Planar cracks through each cracking impact point (1: the physical answer)")
    seed: IntProperty(name="Seed", min=0, default=0, description="Seed of the random choices; runs repeat exactly")
    crack_length: FloatProperty(name="Crack Length", min=0.0, default=0.0, unit="LENGTH",
                                description="How far a crack runs from its impact point (0: as far as the stress "
                                            "exceeds the strength)")
    impact_force_threshold: FloatProperty(name="Force Threshold [N]", min=0.0, default=0.0,
                                          description="Touches below this force are never analysed [N]")
    min_fragment_particles: IntProperty(name="Smallest Piece", min=1, default=8,
                                        description="Pieces with fewer particles are merged into a neighbour")
    refracture: BoolProperty(name="Pieces Break Again", default=True,
                             description="Fragments may break again on later impacts")
    stress_model: EnumProperty(name="Stress Model", items=STRESS_MODELS, default="auto")
    crack_roughness: FloatProperty(name="Crack Roughness", min=0.0, default=0.0, unit="LENGTH",
                                   description="Amplitude of the noise on rendered crack faces (0: flat)")
    # Initial motion.
    velocity_source: EnumProperty(
        name="Velocity", default="MANUAL",
        items=(("MANUAL", "Given", "The velocities below"),
               ("ANIMATION", "From Animation", "The slope of the object's keyframed motion at the start frame")))
    linear_velocity: FloatVectorProperty(name="Linear Velocity", size=3, subtype="VELOCITY", unit="VELOCITY",
                                         description="Initial velocity of the centre of mass, world [m/s]")
    angular_velocity: FloatVectorProperty(name="Angular Velocity [rad/s]", size=3,
                                          description="Initial angular velocity, world [rad/s]")
    hidden_by_simulation: BoolProperty(
        name="Hidden by Simulation", description="Hidden because its pieces show (Simulate shows it again to export it)")
    # What the last simulation found (written by the Simulate operator).
    result_state: EnumProperty(
        name="Result", default="NONE",
        items=(("NONE", "Not Simulated", ""), ("BROKE", "Broke", ""), ("UNBROKEN", "Did Not Break", "")))
    result_peak_stress: FloatProperty(name="Peak Stress [Pa]", description="Largest principal stress reached [Pa]")
    result_strength: FloatProperty(name="Strength [Pa]", description="The strength it was compared with [Pa]")
    result_frame: FloatProperty(name="Peak Frame", description="Scene frame of the peak (-1: no analysed impact)")
    result_point: FloatVectorProperty(name="Peak At", size=3, subtype="TRANSLATION",
                                      description="Where the peak stress was, world (at the end of that frame)")
    result_break_speed: FloatProperty(name="Speed to Break [m/s]",
                                      description="Estimated impact speed that would break it (0: no estimate)")
    result_impact_speed: FloatProperty(name="Impact Speed [m/s]", description="Approach speed of that impact")
    result_note: StringProperty(name="Diagnosis", description="Why it did not break, in one line")


class TaichiFracSimScene(bpy.types.PropertyGroup):
    """``Scene.taichi_frac_sim``: the whole run's settings. The frame range and frame rate
    are the scene's own."""

    ground: BoolProperty(name="Ground", default=True, description="An infinite ground plane")
    ground_height: FloatProperty(name="Height", default=0.0, unit="LENGTH", description="The ground plane's height")
    particles: IntProperty(name="Particles per Body", min=50, max=5_000_000, default=2000,
                           description="Physics particles (tets) each breakable body is discretised into: more "
                                       "gives finer cracks and costs more")
    substeps: IntProperty(name="Substeps", min=1, max=1000, default=10, description="Solver substeps per frame")
    draft: BoolProperty(
        name="Draft", default=False,
        description="A quick look: the pieces are cut on the cracks as the analysis placed them, without the "
                    "cuts that fit each piece's volume to its tets' (the same physics; pieces a few per cent "
                    "off their volume)")
    cache_path: StringProperty(
        name="Cache", subtype="FILE_PATH", default="",
        description="The cache file (.usdc); the scene file and meshes go beside it. Empty: a folder "
                    "'taichi_frac' beside the .blend (a temporary folder while the file is unsaved)")
    last_message: StringProperty(name="Last Run", description="What the last simulation reported")


classes = (TaichiFracSimObject, TaichiFracSimScene)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Object.taichi_frac_sim = PointerProperty(type=TaichiFracSimObject)
    bpy.types.Scene.taichi_frac_sim = PointerProperty(type=TaichiFracSimScene)


def unregister():
    del bpy.types.Scene.taichi_frac_sim
    del bpy.types.Object.taichi_frac_sim
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
