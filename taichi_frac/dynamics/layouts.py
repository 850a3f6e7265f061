"""Row layouts of the arrays that carry bodies and impacts between the host and the
kernels, each defined once: the kernels index a row by a layout's named column starts
(compile-time constants), the host builds and splits rows by the same names.

A row array moves K bodies or impact rows in one kernel launch: every array argument of a
launch costs ~11 us of Python, and a field read from the host is a launch of its own.
"""

from __future__ import annotations

import numpy as np


class RowLayout:
    """Named, consecutive column ranges of a row: ``layout.<name>`` is the first column of
    ``name`` (an int, usable in a kernel), ``layout.width`` the row's length."""

    def __init__(self, **widths: int):
        self.widths = dict(widths)
        start = 0
        self.starts: dict[str, int] = {}
        for name, width in widths.items():
            self.starts[name] = start
            setattr(self, name, start)
            start += width
        self.width = start

    def row(self, **values) -> np.ndarray:
        """One row (width,) float64 from a value for every column range, in any order."""
        if set(values) != set(self.widths):
            raise ValueError(f"a row needs exactly {sorted(self.widths)}, got {sorted(values)}")
        out = np.empty(self.width, dtype=np.float64)
        for name, value in values.items():
            start, width = self.starts[name], self.widths[name]
            out[start:start + width] = np.ravel(np.asarray(value, dtype=np.float64))
        return out

    def split(self, rows: np.ndarray, integers=()) -> dict:
        """{name: rows[:, its columns]} of rows (K, width): (K,) for a one-column range
        (as int32 for the names in ``integers``), (K, width) views otherwise."""
        out = {}
        for name, start in self.starts.items():
            width = self.widths[name]
            column = rows[:, start] if width == 1 else rows[:, start:start + width]
            out[name] = column.astype(np.int32) if name in integers else column
        return out


#: A body's state as ``World.body_state`` and ``checkpoint_state`` read it (f64 rows of the
#: f32 / i32 fields: exact): position [m], orientation wxyz, linear [m/s] and angular
#: [rad/s] velocity, active and sleeping (0 / 1).
BODY_STATE = RowLayout(position=3, orientation=4, linear_velocity=3, angular_velocity=3, active=1, sleeping=1)

#: A body as ``World.add_bodies`` writes it (f32): its pose and velocities, inertia and
#: inverse inertia about the COM in body axes (row-major 3x3) [kg m^2], [1/(kg m^2)],
#: inverse mass [1/kg], friction, restitution, contact compliance [1/Pa], contact radius
#: [m], and its sphere grid's body-frame origin [m], cell edge [m] and cells per axis
#: (``collision.grid.body_grid``).
BODY_WRITE = RowLayout(position=3, orientation=4, linear_velocity=3, angular_velocity=3, inertia=9,
                       inverse_inertia=9, inverse_mass=1, friction=1, restitution=1, contact_compliance=1,
                       contact_radius=1, grid_origin=3, grid_edge=1, grid_dims=3)

#: The integers of a body ``World.add_bodies`` writes (i32): its body slot, first particle
#: slot, fixed (0 / 1), its collision spheres' first and last + 1 row of the spheres array,
#: its grid entries' first and last + 1 row of the grid array, and the cluster spheres
#: asked.
BODY_WRITE_INTS = RowLayout(slot=1, particle_start=1, fixed=1, spheres=1, spheres_end=1, grid=1, grid_end=1,
                            clusters=1)

#: An impact row as ``World.impacts`` returns it (f64): body, other (-1 ground, -2 static
#: box), point [m], normal (unit, into body), impulse [N s] and force [N] on body, Hertz
#: duration [s], approach speed [m/s], substep length [s], substep, and point, normal and
#: force in the body's frame at that substep.
IMPACT = RowLayout(body=1, other=1, point=3, normal=3, impulse=3, force=3, duration=1, speed=1, dt=1, substep=1,
                   point_body=3, normal_body=3, force_body=3)
IMPACT_INTEGERS = ("body", "other", "substep")
