"""Fracture: contact stress analysis and, beside it, cracks and fragments.

Stress analysis of one impact (BRIEF.md §1 steps 5-8), all f64, body frame, SI units:

- :func:`contact_field` -- the whole chain for one contact force (``api.py``);
- :func:`body_stress` -- the stress at a tet mesh's centroids under a step's contacts, by
  any stress model: "halfspace" (``halfspace.py``), "sph", "fem" (``fem.py``);
- :func:`point_load_displacement` -- Boussinesq-Cerruti displacement (``field.py``);
- :func:`neighbor_lists`, :func:`displacement_gradient` -- SPH (``sph.py``);
- :func:`stress_from_gradient`, :func:`principal_stresses`, :func:`rankine_flags`
  (``stress.py``).
"""

from .api import BodyStress, ContactField, body_stress, contact_field
from .field import contact_frame, point_load_displacement
from .sph import (
    CORRECTION_MIN_EIGEN_RATIO,
    default_smoothing_length,
    displacement_gradient,
    kernel_values,
    neighbor_lists,
)
from .stress import green_strain, lame_parameters, principal_stresses, rankine_flags, stress_from_gradient

__all__ = [
    "CORRECTION_MIN_EIGEN_RATIO",
    "BodyStress",
    "ContactField",
    "body_stress",
    "contact_field",
    "contact_frame",
    "default_smoothing_length",
    "displacement_gradient",
    "green_strain",
    "kernel_values",
    "lame_parameters",
    "neighbor_lists",
    "point_load_displacement",
    "principal_stresses",
    "rankine_flags",
    "stress_from_gradient",
]
