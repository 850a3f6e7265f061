"""Names, units and version of the taichi-frac USD cache (one place; the Blender add-on keeps
a copy in ``blender_addon/taichi_frac_blender/schema.py`` that tests/test_usd_cache.py checks
against this one).

Layout of a cache (time code = frame number, ``timeCodesPerSecond`` = fps):

    /Fracture                      Xform, the default prim
        Materials/outer, inner     UsdPreviewSurface materials (original surface / crack faces)
        Fragments/<name>           one Mesh per fragment, points in its body frame,
                                   xformOp:translate + xformOp:orient time-sampled (world pose),
                                   visibility time-sampled (invisible before birth, after death),
                                   GeomSubsets ``outer`` and ``inner`` (family materialBind)

Units: metres scaled by the stage's ``metersPerUnit``; forces in newtons, stress in pascals
(both SI whatever ``metersPerUnit`` says: they are physical data, not scene geometry).
"""

from __future__ import annotations

SCHEMA_VERSION = 1
ROOT_PRIM = "/Fracture"
MATERIALS_SCOPE = "/Fracture/Materials"
FRAGMENTS_SCOPE = "/Fracture/Fragments"

OUTER_SUBSET = "outer"          # faces that were on the input mesh's surface
INNER_SUBSET = "inner"          # crack faces
SUBSET_FAMILY = "materialBind"

# Custom attributes on each fragment Mesh (namespace "taichiFrac:").
ATTR_BIRTH_FRAME = "taichiFrac:birthFrame"          # int, first frame the fragment is visible
ATTR_DEATH_FRAME = "taichiFrac:deathFrame"          # int, first frame it is gone; -1 = never
ATTR_PARENT = "taichiFrac:parent"                   # relationship to the parent fragment's prim
ATTR_IMPACT_POINT = "taichiFrac:impactPoint"        # point3d, world frame (stage units)
ATTR_IMPACT_FORCE = "taichiFrac:impactForce"        # vector3d [N], world frame
ATTR_PEAK_STRESS = "taichiFrac:peakPrincipalStress"  # double [Pa], largest over the fragment
PRIMVAR_FACE_STRESS = "peakPrincipalStress"         # float per face (uniform) [Pa]
PRIMVAR_UV = "st"                                   # texCoord2f, faceVarying

# Layer customLayerData["taichiFrac"] keys.
LAYER_DATA_KEY = "taichiFrac"
KEY_VERSION = "schemaVersion"
KEY_COMPLETE = "complete"        # False in a checkpoint of an unfinished (or crashed) run
KEY_LAST_FRAME = "lastFrame"     # last frame whose poses are in the file
KEY_GENERATOR = "generator"
