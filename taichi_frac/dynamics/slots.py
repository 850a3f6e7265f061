"""Where each body lives in the World's fixed-capacity fields: its body slot, its
contiguous range of collision-particle slots and its range of contact-patch points.
Host bookkeeping only (Python lists and dicts); the World writes the fields."""

from __future__ import annotations

from .options import CapacityError, WorldCapacity


class SlotAllocator:
    """Body slots (freed slots reused, lowest first out in the order they were freed) and
    first-fit ranges of particle slots and patch points.

    Attributes:
        body_range: {body slot: (first particle slot, particle count)} of the bodies in
            the world.
        point_range: {body slot: (first patch point, point count)} of the bodies that have
            contact patches.
        particles_in_use: particle slots held by bodies.
        body_slot_end, particle_slot_end: one past the highest body / particle slot ever
            used since the last :meth:`clear` (the kernels loop to them).
    """

    def __init__(self, capacity: WorldCapacity):
        self.capacity = capacity
        self.clear()

    def clear(self) -> None:
        """Every slot and range free."""
        self.free_body_slots: list[int] = []
        self.body_slot_end = 0
        self.free_ranges: list[tuple[int, int]] = [(0, self.capacity.max_boundary_particles)]  # (start, count)
        self.body_range: dict[int, tuple[int, int]] = {}
        self.particles_in_use = 0
        self.free_points: list[tuple[int, int]] = [(0, self.capacity.max_surface_points)]  # (start, count)
        self.point_range: dict[int, tuple[int, int]] = {}
        self.particle_slot_end = 0

    def take(self, particle_counts, point_counts) -> tuple[list[tuple[int, int, int]], list[int]]:
        """A body slot and a particle range for each of ``particle_counts``, and a point
        range for each of ``point_counts``: ([(slot, first particle, count)], [first
        point]). All or nothing: a full capacity raises CapacityError with every slot and
        range given back (so the slots go out again in the same order)."""
        taken = []
        point_starts = []
        try:
            for count in particle_counts:
                slot = self._allocate_body_slot()
                taken.append((slot, self._allocate_particles(count, slot_for_error=slot), count))
            for count in point_counts:
                point_starts.append(self._allocate_points(count))
        except CapacityError:
            for slot, start, n in reversed(taken):
                self.free_body_slots.insert(0, slot)
                self.free_ranges = _give_range(self.free_ranges, start, n)
            for first, count in zip(point_starts, point_counts):
                self.free_points = _give_range(self.free_points, first, count)
            raise
        return taken, point_starts

    def hold(self, slot: int, start: int, count: int) -> None:
        """Record body ``slot`` as holding particles [start, start + count)."""
        self.body_range[slot] = (start, count)
        self.particles_in_use += count
        self.particle_slot_end = max(self.particle_slot_end, start + count)

    def release(self, body: int) -> tuple[int, int]:
        """Free body ``body``'s slot, particle range and patch points; returns its
        (first particle slot, particle count)."""
        start, count = self.body_range.pop(body)
        self.free_body_slots.append(body)
        self.free_ranges = _give_range(self.free_ranges, start, count)
        self.particles_in_use -= count
        if body in self.point_range:
            self.free_points = _give_range(self.free_points, *self.point_range.pop(body))
        return start, count

    def _allocate_body_slot(self) -> int:
        if self.free_body_slots:
            return self.free_body_slots.pop(0)
        if self.body_slot_end >= self.capacity.max_bodies:
            raise CapacityError(f"more than max_bodies={self.capacity.max_bodies} bodies: "
                                "raise WorldCapacity(max_bodies=...)")
        self.body_slot_end += 1
        return self.body_slot_end - 1

    def _allocate_particles(self, count: int, slot_for_error: int) -> int:
        start = _take_range(self.free_ranges, count)
        if start is not None:
            return start
        self.free_body_slots.insert(0, slot_for_error)
        raise CapacityError(
            f"no room for {count} more collision particles: {self.particles_in_use} of "
            f"max_boundary_particles={self.capacity.max_boundary_particles} in use "
            f"(largest free range {max((f for _, f in self.free_ranges), default=0)}): "
            "raise WorldCapacity(max_boundary_particles=...)")

    def _allocate_points(self, count: int) -> int:
        start = _take_range(self.free_points, count)
        if start is None:
            raise CapacityError(
                f"no room for {count} more contact-patch points (max_surface_points="
                f"{self.capacity.max_surface_points}, largest free range "
                f"{max((f for _, f in self.free_points), default=0)}): raise WorldCapacity(max_surface_points=...)")
        return start


def _take_range(ranges: list, count: int):
    """First fit: the start of ``count`` slots taken from the free ``ranges`` [(start,
    count)] (updated in place), or None when no range is large enough."""
    for k, (start, free) in enumerate(ranges):
        if free >= count:
            if free == count:
                ranges.pop(k)
            else:
                ranges[k] = (start + count, free - count)
            return start
    return None


def _give_range(ranges: list, start: int, count: int) -> list:
    """The free ``ranges`` with [start, start + count) given back, neighbours merged."""
    merged: list[tuple[int, int]] = []
    for s, n in sorted(ranges + [(start, count)]):
        if merged and merged[-1][0] + merged[-1][1] == s:
            merged[-1] = (merged[-1][0], merged[-1][1] + n)
        else:
            merged.append((s, n))
    return merged
