"""Preallocated Taichi fields of the rigid-body world (allocated once, slots reused).

Containers only: kernels live in ``collision/`` and ``dynamics/{integrate,solver}.py`` and
take these objects as ``ti.template()`` arguments (always the same objects, so every kernel
compiles once). Floats are the runtime default (f32); indices i32. "Writer" names the stage
that writes each array.
"""


from ..runtime import ti
from ..collision.grid import CELLS_PER_SPHERE
from ..geometry.contact_patches import MAX_FACETS

vec3 = ti.math.vec3
vec4 = ti.math.vec4
mat3 = ti.math.mat3
#: Contacts remembered per particle for warm starting. A particle's patch touches the
#: ground at up to four points and its neighbours' patches besides; contacts past the
#: slots start cold every substep, and a heap of chips then never settles.
CACHE_SLOTS = 8
# Hull searches remembered per particle (``Particles.hull_direction``): a ring's sphere
# resting on another ring searches with two to five of its spheres.
HULL_SLOTS = 8
# Cluster spheres per body for the narrowphase's pre-test (a sphere near one of them reads
# the body's grid; narrowphase._pair_contacts): one per 16 collision spheres, at most this
# many (16 passes about half as many spheres as the box alone, 8 noticeably more, 32 few
# fewer). A small fragment gets one (its bounding sphere): a sphere each costs more.
MAX_CLUSTERS = 16


@ti.data_oriented
class BodyMotion:
    """The bodies' motion state, shape (capacity,): everything a step changes that a later
    step reads, so a copy of it (``checkpoints.py``) is a checkpoint.

    Fields:
        position: vec3 [m] world position of the centre of mass. Writer: add_body, integrate.
        orientation: vec4 (w, x, y, z) unit, body -> world. Writer: add_body, integrate.
        linear_velocity: vec3 [m/s]. Writer: add_body, integrate_velocities, solver.
        angular_velocity: vec3 [rad/s], world frame. Writer: same.
        sleeping: i32 1 = asleep. sleep_timer: [s] time spent slow or still. Writer: integrate, wake.
        sleep_anchor, sleep_anchor_orientation: vec3 [m], vec4: the pose the body has stayed
            near (``kinematics.bounds.anchor_drift``); moved to the body's pose whenever it
            leaves it. Writer: add_body, integrate.
        wake_request: i32 set by the narrowphase when an awake moving body touches a
            sleeping one; applied at the start of the next substep's broadphase (body_cull).
    """

    def __init__(self, capacity: int):
        self.position = vec3.field(shape=capacity)
        self.orientation = vec4.field(shape=capacity)
        self.linear_velocity = vec3.field(shape=capacity)
        self.angular_velocity = vec3.field(shape=capacity)
        self.sleeping = ti.field(ti.i32, shape=capacity)
        self.sleep_timer = ti.field(ti.f32, shape=capacity)
        self.sleep_anchor = vec3.field(shape=capacity)
        self.sleep_anchor_orientation = vec4.field(shape=capacity)
        self.wake_request = ti.field(ti.i32, shape=capacity)


@ti.data_oriented
class Bodies:
    """Per-body fields, shape (max_bodies,). A slot with ``active == 0`` is free. Three
    kinds: the motion state (``motion_state``, a :class:`BodyMotion`, whose fields are also
    attributes here so kernels read ``bodies.position``), the static data written once
    when a body is added, and per-substep scratch.

    Static fields (Writer: add_body, unless named):
        inverse_mass: [1/kg], 0 for fixed bodies.
        inertia_body: mat3 [kg m^2] about the COM, body axes.
        inverse_inertia_body: mat3 [1/(kg m^2)], body axes, 0 for fixed bodies.
        friction: Coulomb coefficient [-]. restitution: [-].
        contact_compliance: (1 - nu^2) / E [1/Pa], 0 for a rigid body; contact_radius [m],
            the radius of the sphere it impacts like (Hertz peak force of impact rows, see
            impacts.py).
        active: i32 1 = slot in use. fixed: i32 1 = never moves. Writer: add_body/remove_body.
        bounding_radius: [m] max |offset| + radius (+ the patch's ``Particles.overhang``)
            over the body's particles.
        mean_particle_radius, max_particle_radius: [m] of its collision particles
            (substep refinement, contact reach).
        local_lower, local_upper: vec3 [m] body-frame box holding every collision sphere
            and contact patch.
        cluster (capacity, MAX_CLUSTERS) vec4: body-frame spheres (centre [m], radius [m])
            that each enclose a group of its collision spheres; cluster_count: how many.
            (``clusters.py``)
        particle_start, particle_count: i32 its contiguous range of particle slots.
        grid_origin: vec3 [m] body-frame corner of its sphere grid (``collision/grid.py``),
            grid_edge: [m] cell edge, grid_dims: ivec3 cells per axis.

    Scratch fields (rewritten every substep before they are read):
        pseudo_linear_velocity, pseudo_angular_velocity: vec3 split-impulse velocities
            (penetration push-out, never kinetic energy). Writer: solver; cleared by integrate.
        solver_inverse_mass: [1/kg], this substep (0 when sleeping or fixed).
            Writer: integrate_velocities.
        solver_inverse_inertia: mat3 world-frame inverse inertia this substep (0 when
            sleeping or fixed). Writer: integrate_velocities.
        sleep_blocked: i32 1 = an awake body it touches has not been slow for sleep_time
            (so it may not sleep this substep). Writer: integrate.sleep_together.
        touched: i32 1 = the body has a contact this substep (free-flying bodies are moved
            by the exact ballistic step). Writer: prepare_contacts.
        rotation: mat3 body -> world this substep. motion: [m] bound on how far any of its
            points moves in this substep ((|v| + |w| bounding_radius) dt; 0 when idle).
        near_body, near_static: i32 culling flags (its motion-grown bounding sphere reaches
            another body / a static collider this substep).
        neighbor_count, neighbors (capacity, max_neighbors): bodies whose grown bounding
            spheres overlap its own (one of the two awake); more than max_neighbors sets
            neighbor_count = -1 (then every particle of the body is tested).
        neighbor_motion (capacity, max_neighbors): [m] how far the gap to each neighbour
            may close this substep (``kinematics.bounds.pair_motion``).
            Writer of rotation ... neighbor_motion: body_cull (broadphase).
    """

    def __init__(self, capacity: int, max_neighbors: int = 128):
        self.capacity = capacity
        self.max_neighbors = max_neighbors
        # Motion state.
        self.motion_state = BodyMotion(capacity)
        self.position = self.motion_state.position
        self.orientation = self.motion_state.orientation
        self.linear_velocity = self.motion_state.linear_velocity
        self.angular_velocity = self.motion_state.angular_velocity
        self.sleeping = self.motion_state.sleeping
        self.sleep_timer = self.motion_state.sleep_timer
        self.sleep_anchor = self.motion_state.sleep_anchor
        self.sleep_anchor_orientation = self.motion_state.sleep_anchor_orientation
        self.wake_request = self.motion_state.wake_request
        # Static.
        self.inverse_mass = ti.field(ti.f32, shape=capacity)
        self.inertia_body = mat3.field(shape=capacity)
        self.inverse_inertia_body = mat3.field(shape=capacity)
        self.friction = ti.field(ti.f32, shape=capacity)
        self.contact_compliance = ti.field(ti.f32, shape=capacity)
        self.contact_radius = ti.field(ti.f32, shape=capacity)
        self.restitution = ti.field(ti.f32, shape=capacity)
        self.active = ti.field(ti.i32, shape=capacity)
        self.fixed = ti.field(ti.i32, shape=capacity)
        self.bounding_radius = ti.field(ti.f32, shape=capacity)
        self.mean_particle_radius = ti.field(ti.f32, shape=capacity)
        self.max_particle_radius = ti.field(ti.f32, shape=capacity)
        self.local_lower = vec3.field(shape=capacity)
        self.local_upper = vec3.field(shape=capacity)
        self.cluster = vec4.field(shape=(capacity, MAX_CLUSTERS))
        self.cluster_count = ti.field(ti.i32, shape=capacity)
        self.particle_start = ti.field(ti.i32, shape=capacity)
        self.particle_count = ti.field(ti.i32, shape=capacity)
        self.grid_origin = vec3.field(shape=capacity)
        self.grid_edge = ti.field(ti.f32, shape=capacity)
        self.grid_dims = ti.math.ivec3.field(shape=capacity)
        # Scratch.
        self.pseudo_linear_velocity = vec3.field(shape=capacity)
        self.pseudo_angular_velocity = vec3.field(shape=capacity)
        self.solver_inverse_mass = ti.field(ti.f32, shape=capacity)
        self.solver_inverse_inertia = mat3.field(shape=capacity)
        self.sleep_blocked = ti.field(ti.i32, shape=capacity)
        self.touched = ti.field(ti.i32, shape=capacity)
        self.rotation = mat3.field(shape=capacity)
        self.motion = ti.field(ti.f32, shape=capacity)
        self.neighbor_count = ti.field(ti.i32, shape=capacity)
        self.neighbors = ti.field(ti.i32, shape=(capacity, max_neighbors))
        self.neighbor_motion = ti.field(ti.f32, shape=(capacity, max_neighbors))
        self.near_body = ti.field(ti.i32, shape=capacity)
        self.near_static = ti.field(ti.i32, shape=capacity)
        # Scalar: one past the highest slot in use (loops run to it).
        self.slot_end = ti.field(ti.i32, shape=())


@ti.data_oriented
class Particles:
    """Collision spheres, shape (max_boundary_particles,). ``body == -1``: free slot.

    Fields:
        body: i32 owning body slot. Writer: add_body / remove_body.
        offset: vec3 [m] centre in the body frame. radius: [m]. Writer: add_body.
        Its body's sphere grid (``collision/grid.py``), in the body's slot range [start,
        start + count) but in cell order: grid_sphere vec4 (body-frame centre [m], radius
        [m]) and grid_slot (i32, that sphere's particle slot) of entry k; cell_first,
        shape (C x capacity,), C = ``grid.CELLS_PER_SPHERE``: the body's cell c holds the
        entries cell_first[C start + c] .. cell_first[C start + c + 1] (a grid has at most
        C count - 1 cells, so a body's cell starts fit in its share). Writer: add_body.
        order_stamp, order_start: i32, the contacts' counting sort by querying particle
            (narrowphase.order_contacts): the sort that counted the particle last, and
            where its contacts start in ``Contacts.order``.
        Contact cache (warm starting), two halves (previous / next substep), ``parity``
        names the previous one: cache_count (2, P) contacts kept for particle P as the
        querying side; cache_key (2, P, CACHE_SLOTS) partner (particle slot >= 0; a static
        collider's contacts ``narrowphase.POINT_KEYS``' keys, one per patch point);
        cache_normal [N s], cache_tangent (vec3, [N s]) their accumulated impulses;
        cache_stamp (2, P) the store that wrote the particle's entries (only the last
        store, ``cache_epoch``, is valid; add_body sets -1 on a reused slot). Writer:
        solver.store_impulses; read by the narrowphase when the same pair is made again.
        Hull searches (``hulls.hull_pair``), in the same two halves: hull_count (2, P)
        searches kept for particle P as the querying side; hull_key (2, P, HULL_SLOTS) the
        partner particle; hull_direction (vec3 unit, partner body frame) the normal found,
        contact or not, where the same pair's search starts next substep; hull_simplex
        (ivec3) the search's last simplex, as ids of pairs of patch rows
        (``surface._corner``), where it resumes; hull_stamp (2, P)
        as cache_stamp (the substep's epoch is ``cache_epoch`` + 1 until the store).
        Writer: the narrowphase (each particle's own thread).
        Contact patches (``geometry.contact_patches.ContactPatches``): point_start, point_count (i32) the rows
            of ``surface_point`` holding sphere P's patch (count 0: the sphere is its own
            surface, the contacts are sphere contacts); patch_normal (vec3 body frame,
            unit outward, or zero where the patch faces every way); patch_facet, shape
            (capacity, MAX_FACETS): vec3 body frame, the planes its triangles lie in
            (``ContactPatches.facets``; zero rows unused, all zero: none). surface_point, shape
            (max_surface_points,): vec3 [m] body-frame points of the patches, each body's
            in one contiguous range. overhang (f32 [m]): how far sphere P's patch reaches
            past the sphere (a sphere covers its members' centroids, not every corner of
            their boundary triangles: a chip's patch stood out of its sphere by 3 mm); the
            narrowphase looks that much further before it tries the patch. Writer: add_body.
        slot_end: one past the highest slot in use.
    """

    def __init__(self, capacity: int, max_surface_points: int = 1):
        self.capacity = capacity
        self.point_start = ti.field(ti.i32, shape=capacity)
        self.point_count = ti.field(ti.i32, shape=capacity)
        self.patch_normal = vec3.field(shape=capacity)
        self.overhang = ti.field(ti.f32, shape=capacity)
        self.patch_facet = vec3.field(shape=(capacity, MAX_FACETS))
        self.surface_point = vec3.field(shape=max_surface_points)
        self.body = ti.field(ti.i32, shape=capacity)
        self.offset = vec3.field(shape=capacity)
        self.radius = ti.field(ti.f32, shape=capacity)
        self.grid_sphere = vec4.field(shape=capacity)
        self.grid_slot = ti.field(ti.i32, shape=capacity)
        self.cell_first = ti.field(ti.i32, shape=CELLS_PER_SPHERE * capacity)
        self.cache_count = ti.field(ti.i32, shape=(2, capacity))
        self.cache_key = ti.field(ti.i32, shape=(2, capacity, CACHE_SLOTS))
        self.cache_normal = ti.field(ti.f32, shape=(2, capacity, CACHE_SLOTS))
        self.cache_tangent = vec3.field(shape=(2, capacity, CACHE_SLOTS))
        self.hull_count = ti.field(ti.i32, shape=(2, capacity))
        self.hull_key = ti.field(ti.i32, shape=(2, capacity, HULL_SLOTS))
        self.hull_direction = vec3.field(shape=(2, capacity, HULL_SLOTS))
        self.hull_simplex = ti.types.vector(3, ti.i32).field(shape=(2, capacity, HULL_SLOTS))
        self.hull_stamp = ti.field(ti.i32, shape=(2, capacity))
        self.cache_stamp = ti.field(ti.i32, shape=(2, capacity))
        self.parity = ti.field(ti.i32, shape=())
        self.cache_epoch = ti.field(ti.i32, shape=())
        self.order_stamp = ti.field(ti.i32, shape=capacity)
        self.order_start = ti.field(ti.i32, shape=capacity)
        self.slot_end = ti.field(ti.i32, shape=())


@ti.data_oriented
class StepParams:
    """The solver options ``respond`` reads, as scalar fields (each scalar kernel argument
    costs ~2.3 us per launch on the CPU backend: 14 of them would be ~35 us a substep).
    Writer: World (``_write_params``) whenever its options object changes. Names and units
    as in ``DynamicsOptions``."""

    def __init__(self):
        self.iterations = ti.field(ti.i32, shape=())
        self.restitution_iterations = ti.field(ti.i32, shape=())
        self.allowed_penetration = ti.field(ti.f32, shape=())
        self.max_correction_speed = ti.field(ti.f32, shape=())
        self.restitution_threshold = ti.field(ti.f32, shape=())
        self.force_threshold = ti.field(ti.f32, shape=())
        self.impact_speed = ti.field(ti.f32, shape=())
        self.max_rotation = ti.field(ti.f32, shape=())
        self.sleep_linear_speed = ti.field(ti.f32, shape=())
        self.sleep_angular_speed = ti.field(ti.f32, shape=())
        self.sleep_time = ti.field(ti.f32, shape=())
        self.warm_start = ti.field(ti.f32, shape=())
        self.rolling_resistance = ti.field(ti.f32, shape=())


@ti.data_oriented
class Statics:
    """Static colliders: ground planes and oriented boxes.

    Fields:
        plane_height: [m] z of each horizontal ground plane; plane_friction,
            plane_restitution [-]. plane_count: scalar.
        box_center: vec3 [m]; box_rotation: mat3 box -> world; box_half_extents: vec3 [m];
            box_friction, box_restitution [-]. box_count: scalar. Writer: add_ground/add_static_box.
        gravity: vec3 scalar [m/s^2] (a field, not a kernel argument: a vector argument
            costs ~50 us per launch on the CPU backend). Writer: World.set_options.
    """

    def __init__(self, max_planes: int, max_boxes: int):
        self.max_planes = max_planes
        self.max_boxes = max_boxes
        self.plane_height = ti.field(ti.f32, shape=max_planes)
        self.plane_friction = ti.field(ti.f32, shape=max_planes)
        self.plane_restitution = ti.field(ti.f32, shape=max_planes)
        self.plane_count = ti.field(ti.i32, shape=())
        self.box_center = vec3.field(shape=max_boxes)
        self.box_rotation = mat3.field(shape=max_boxes)
        self.box_half_extents = vec3.field(shape=max_boxes)
        self.box_friction = ti.field(ti.f32, shape=max_boxes)
        self.box_restitution = ti.field(ti.f32, shape=max_boxes)
        self.box_count = ti.field(ti.i32, shape=())
        self.gravity = vec3.field(shape=())
