"""Free motion against closed form: free fall, ballistic flight, torque-free rotation."""

import numpy as np
import pytest

from support.bodies import box_model, sphere_model
from support.dynamics import fresh_world, rotation

G = 9.81


def test_free_fall_and_ballistic_flight_match_closed_form():
    world = fresh_world()
    model = box_model(0.1, 0.1, 0.1)
    x0 = np.array([0.0, 0.0, 50.0])
    v0 = np.array([3.0, -1.0, 4.0])
    body = world.add_body(model, x0, (1, 0, 0, 0), v0, (0.0, 0.0, 0.0))
    frame_dt, substeps, frames = 0.02, 10, 50
    for _ in range(frames):
        world.advance(frame_dt, substeps)
    t = frames * frame_dt
    state = world.body_state([body])
    exact = x0 + v0 * t + 0.5 * np.array([0, 0, -G]) * t * t
    # A body touching nothing takes exact constant-gravity steps (x += v dt + g dt^2 / 2):
    # what is left is float32 round-off (positions near 50 m carry ~4e-6 m each).
    np.testing.assert_allclose(state["position"][0], exact, atol=2e-4)
    np.testing.assert_allclose(state["linear_velocity"][0], v0 + np.array([0, 0, -G]) * t, atol=2e-4)
    assert world.stats.substeps == 1  # free flight, not spinning: one substep per frame is exact


def test_torque_free_asymmetric_body_conserves_momentum_and_energy():
    world = fresh_world()
    model = box_model(0.06, 0.12, 0.24)  # three distinct principal moments
    omega0 = np.array([0.8, 6.0, 0.8])  # near the unstable intermediate axis: it tumbles
    body = world.add_body(model, (0.0, 0.0, 100.0), (1, 0, 0, 0), (0, 0, 0), omega0)

    def invariants():
        state = world.body_state([body])
        rot = rotation(state["orientation"][0])
        inertia = rot @ model.inertia @ rot.T
        w = state["angular_velocity"][0]
        return inertia @ w, 0.5 * w @ inertia @ w, w

    momentum0, energy0, _ = invariants()
    max_angle = 0.0
    for _ in range(150):
        world.advance(0.02, 10)
        momentum, energy, w = invariants()
        np.testing.assert_allclose(momentum, momentum0, rtol=0, atol=1.5e-3 * np.linalg.norm(momentum0))  # f32 state: I, I^-1 round-off
        assert abs(energy - energy0) <= 2e-3 * energy0
        cosine = w @ omega0 / (np.linalg.norm(w) * np.linalg.norm(omega0))
        max_angle = max(max_angle, np.arccos(np.clip(cosine, -1, 1)))
        # Free flight takes one substep per frame; the body turns in pieces of at most
        # max_rotation_per_substep inside it, so its spin shortens no one's substep.
        assert world.stats.substeps == 1
    assert max_angle > 0.5  # w really wanders (gyroscopic term active), L stays put


def test_checkpoint_restore_puts_bodies_back_exactly():
    """World.restore returns the chosen bodies to their checkpoint bit for bit (pose,
    velocities, sleep state), and leaves the others where the run took them;
    checkpoint_state reads the kept state back."""
    world = fresh_world()
    world.add_ground(0.0)
    model = sphere_model(0.05)
    a = world.add_body(model, (0, 0, 0.3), (1, 0, 0, 0), (0.5, 0, 0), (0, 2.0, 0))
    b = world.add_body(model, (0.5, 0, 0.3), (0.8, 0.6, 0, 0), (0, 0, -1.0), (1.0, 0, 0))
    before = world.body_state([a, b])
    snap = world.checkpoint()
    for _ in range(5):
        world.advance(0.02, 4)
    moved = world.body_state([a, b])
    kept = world.checkpoint_state(snap, [b, a])
    for key in ("position", "orientation", "linear_velocity", "angular_velocity", "sleeping"):
        np.testing.assert_array_equal(kept[key], before[key][::-1], err_msg=key)
    world.restore(snap, [a])
    after = world.body_state([a, b])
    for key in ("position", "orientation", "linear_velocity", "angular_velocity", "sleeping"):
        np.testing.assert_array_equal(after[key][0], before[key][0], err_msg=key)
        np.testing.assert_array_equal(after[key][1], moved[key][1], err_msg=key)
    assert not np.allclose(moved["position"][0], before["position"][0])
    with pytest.raises(KeyError):
        world.restore(snap, [a, 999])
    world.checkpoint()  # only the latest checkpoint is kept
    with pytest.raises(ValueError, match="stale"):
        world.restore(snap, [a])


def test_a_substep_run_again_after_a_restore_gives_the_plain_advance():
    """The caller drives the frame (begin_frame, substep k, end_frame) and may run a
    substep again after restoring the bodies to a checkpoint taken before it (the
    simulation does after a fracture); the substep run twice gives the frame a plain
    advance gives, bit for bit, and the frame's statistics are advance's."""
    results, calls = [], []
    for driven in (False, True):
        world = fresh_world()
        world.add_ground(0.0)
        model = sphere_model(0.05)
        body = world.add_body(model, (0, 0, 0.0498), (1, 0, 0, 0), (0.4, 0, -0.5), (0, 3.0, 0))  # on the ground
        if not driven:
            world.advance(0.02, 4)
            plain_substeps = world.stats.substeps
        else:
            count = world.begin_frame(0.02, 4)
            for k in range(count):
                calls.append(("before", k))
                snap = world.checkpoint()
                world.substep(0.02 / count, k)
                calls.append(("after", k))
                if k == 1:
                    world.restore(snap, world.body_ids)
                    world.substep(0.02 / count, k)
                    calls.append(("after", k))
            world.end_frame()
        results.append(world.body_state([body]))
    assert calls[:6] == [("before", 0), ("after", 0), ("before", 1), ("after", 1), ("after", 1), ("before", 2)]
    assert len(calls) == 2 * world.stats.substeps + 1
    assert world.stats.substeps == plain_substeps
    for key in ("position", "orientation", "linear_velocity", "angular_velocity"):
        np.testing.assert_array_equal(results[0][key], results[1][key], err_msg=key)
