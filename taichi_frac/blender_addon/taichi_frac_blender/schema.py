"""Names of the taichi-frac USD cache: a copy of taichi_frac/io/schema.py (the add-on cannot
import taichi_frac). tests/test_usd_cache.py checks the two agree."""

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
