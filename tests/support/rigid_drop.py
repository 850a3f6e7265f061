"""An event-driven rigid-body reference: a polyhedron dropped onto a frictionless plane.

The body (its vertices about the centre of mass, mass, inertia) falls under gravity onto
the plane z = 0. Between impacts its motion is free flight: the centre of mass follows a
parabola exactly, and the orientation turns by the angular velocity (from the conserved
angular momentum) over steps of ``FAR_STEP`` seconds, ``step`` within ``NEAR`` of the
plane, which is exact for a body spinning about a principal axis (a ring tilted about a
diameter). An impact is found at the moment a
vertex reaches the plane (bisection on the step) and resolved then, with no time step:
the touching vertex that approaches fastest takes the impulse along +Z that sends it
back at e times its approach speed (Newton's law; e = 0 below ``bounce_speed``), repeated
until no touching vertex approaches. A vertex that stays on the plane (approaching slower
than ``bounce_speed``) is held by the same impulses after every step.

It shares nothing with the simulator but the body's mass properties, so it checks the
contacts' geometry and the solver's restitution together. Where one vertex strikes at a
time this is the rigid-body answer. Where two strike at the same instant, sequential
impulses are one of several impact laws, so choose drops whose impacts are apart in time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GRAVITY = 9.81  # [m/s^2], along -Z: the default
#: Free-flight step while the lowest vertex is farther than ``NEAR`` [m] above the plane,
#: and the step [s] near it (a pivoting vertex is held once a step).
FAR_STEP = 1e-4
NEAR = 0.005


@dataclass
class RigidDrop:
    """touch_height: the centre of mass's z [m] when a vertex first touches; peak: its
    highest z [m] from then until, having risen, it falls back through ``touch_height``
    (or the window ends); first_impulse: the first impact's impulse [N s]; impacts: (time
    [s] after the first touch, vertex index, approach speed [m/s], impulse [N s]) of every
    impulse applied faster than the bounce speed; simultaneous: how many impacts found two
    or more vertices (within 10 nm of the plane) approaching faster than the bounce speed
    at once, where sequential impulses are not the only answer (0 for a trustworthy
    reference)."""

    touch_height: float
    peak: float
    first_impulse: float
    impacts: list
    simultaneous: int

    @property
    def rebound(self) -> float:
        """[m] how far the centre of mass rises above its height at the first touch."""
        return self.peak - self.touch_height


def _turn(angular_velocity, dt):
    """Rotation matrix (3, 3) of turning at ``angular_velocity`` (3,) [rad/s] for ``dt`` [s]
    (Rodrigues)."""
    speed = float(np.linalg.norm(angular_velocity))
    if speed * dt < 1e-15:
        return np.eye(3)
    k = angular_velocity / speed
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(speed * dt) * cross + (1.0 - np.cos(speed * dt)) * cross @ cross


def drop(vertices, mass: float, inertia, position, rotation, restitution: float, bounce_speed: float,
         window: float = 0.5, step: float = 1e-5, gravity: float = GRAVITY) -> RigidDrop:
    """Drop the body from rest: ``vertices`` (V, 3) [m] in its frame about the centre of
    mass, ``mass`` [kg], ``inertia`` (3, 3) [kg m^2] in its frame, ``position`` (3,) [m]
    of its centre of mass, ``rotation`` (3, 3) body to world, ``gravity`` [m/s^2] along
    -Z. Runs until the first bounce is over (``RigidDrop.peak``) or ``window`` [s] after
    the first touch."""
    vertices = np.asarray(vertices, dtype=np.float64)
    inverse = np.linalg.inv(np.asarray(inertia, dtype=np.float64))
    c = np.array(position, dtype=np.float64)
    rot = np.array(rotation, dtype=np.float64)
    v = np.zeros(3)
    momentum = np.zeros(3)  # angular, world frame [kg m^2/s]
    fall = np.array([0.0, 0.0, -gravity])

    def fly(c, rot, v, dt):
        w = rot @ inverse @ rot.T @ momentum
        return c + v * dt + 0.5 * fall * dt * dt, _turn(w, dt) @ rot, v + fall * dt

    t, first, touch, first_impulse, peak, rose, impacts, simultaneous = 0.0, None, None, 0.0, -np.inf, False, [], 0
    stalled = 0  # impacts in a row found without time passing
    while True:
        lowest = float((vertices @ rot.T + c)[:, 2].min())
        dt = FAR_STEP if lowest > NEAR else step
        c2, rot2, v2 = fly(c, rot, v, dt)
        z = (vertices @ rot2.T + c2)[:, 2]
        if z.min() < 0.0:
            w2 = rot2 @ inverse @ rot2.T @ momentum
            striking = (z < 0.0) & ((v2 + np.cross(w2, vertices @ rot2.T))[:, 2] < -bounce_speed)
            if striking.any():
                # An impact: back to the instant the deepest striking vertex touches (a vertex
                # resting on the plane meanwhile is held at the step's end, as below).
                k = int(np.argmin(np.where(striking, z, np.inf)))
                lo, hi = 0.0, dt
                for _ in range(48):
                    mid = 0.5 * (lo + hi)
                    cm, rm, _ = fly(c, rot, v, mid)
                    lo, hi = (lo, mid) if (rm @ vertices[k] + cm)[2] < 0.0 else (mid, hi)
                dt = lo
                c2, rot2, v2 = fly(c, rot, v, dt)
                stalled = stalled + 1 if dt < 1e-15 else 0
                if stalled > 100:
                    raise RuntimeError(f"the reference stalled at t = {t:.6f} s: an impact it cannot resolve")
            c, rot, v = c2, rot2, v2
            t += dt
            v, applied, striking = _resolve(vertices @ rot.T, rot @ inverse @ rot.T, mass, c, v, momentum,
                                            restitution, bounce_speed)
            simultaneous += striking > 1
            if first is None:
                first, touch, first_impulse = t, float(c[2]), sum(j for _, _, j in applied)
            impacts += [(t - first, vertex, speed, j) for vertex, speed, j in applied if speed > bounce_speed]
        else:
            c, rot, v = c2, rot2, v2
            t += dt
        if first is not None:
            peak = max(peak, float(c[2]))
            rose = rose or v[2] > 0.0
            if t > first + window or (rose and v[2] < 0.0 and c[2] < touch):
                break
        elif t > 100.0:
            raise RuntimeError("the body never reached the plane (is it above z = 0 and falling?)")
    return RigidDrop(touch_height=touch, peak=peak, first_impulse=first_impulse, impacts=impacts,
                     simultaneous=simultaneous)


def _resolve(arms, inverse, mass, c, v, momentum, restitution, bounce_speed):
    """Impulses at the touching vertices (``arms`` (V, 3) [m]: vertices less the centre
    ``c``, world frame; ``inverse`` (3, 3) the world inverse inertia) until none approaches.
    Updates ``momentum`` in place; returns the new velocity, (vertex, approach speed,
    impulse) of each impulse, and how many touching vertices approached faster than
    ``bounce_speed`` before them."""
    heights = arms[:, 2] + c[2]
    touching = np.nonzero(heights < max(float(heights.min()), 0.0) + 1e-8)[0]
    striking = int(((v + np.cross(inverse @ momentum, arms[touching]))[:, 2] < -bounce_speed).sum())
    approach, applied = {}, []
    for _ in range(200):
        w = inverse @ momentum
        normal_speed = (v + np.cross(w, arms[touching]))[:, 2]
        i = int(np.argmin(normal_speed))
        if normal_speed[i] > -1e-12:
            break
        k = int(touching[i])
        speed = approach.setdefault(k, -float(normal_speed[i]))
        lever = np.cross(arms[k], (0.0, 0.0, 1.0))
        j = ((restitution if speed > bounce_speed else 0.0) * speed - normal_speed[i]) \
            / (1.0 / mass + lever @ inverse @ lever)
        v = v + np.array([0.0, 0.0, j / mass])
        momentum += j * lever
        applied.append((k, speed, float(j)))
    return v, applied, striking
