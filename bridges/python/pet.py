"""Post-encroachment time (PET) between the ego and every other vehicle, for any simulator
(``highway_bridge.PetTracker`` for highway-env, ``sumo_bridge`` for SUMO).

The plane is cut into ``PET_CELL_M`` cells; each frame, each vehicle's footprint (a rectangle
of its length and width) covers a set of them. When one vehicle enters a cell that the other
(ego against any other vehicle) has occupied before, with headings more than
``PET_MIN_ANGLE_RAD`` apart (a crossing or a merge, not a car following another in its lane),
the time since the other was last in that cell is a PET: 0 when both are in it at once.
``min_pet`` is the smallest over the episode (inf: no encroachment), ``min_pet_t`` when it
happened. The resolution is the frame period.
"""

import math

import numpy as np

# Cell size of the PET grid, m, and the least heading difference of an encroachment (below
# it two vehicles follow each other, which is a headway, not a post-encroachment time).
PET_CELL_M = 0.5
PET_MIN_ANGLE_RAD = math.radians(30.0)

_footprints = {}


def wrap(angle):
    """``angle`` wrapped to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def footprint_cells(position, heading, length=5.0, width=2.0):
    """The PET grid cells (ix, iy) a ``length`` x ``width`` m vehicle centred at ``position``
    with ``heading`` (rad) covers: sample points at most ``PET_CELL_M`` apart, edges included."""
    pts = _footprints.get((length, width))
    if pts is None:
        nx = int(math.ceil(length / PET_CELL_M)) + 1
        ny = int(math.ceil(width / PET_CELL_M)) + 1
        pts = _footprints[(length, width)] = np.array(
            [(x, y) for x in np.linspace(-length / 2, length / 2, nx)
             for y in np.linspace(-width / 2, width / 2, ny)])
    c, s = math.cos(heading), math.sin(heading)
    world = pts @ np.array([[c, s], [-s, c]]) + np.asarray(position, dtype=float)
    return set(map(tuple, np.floor(world / PET_CELL_M).astype(int).tolist()))


class PetGrid:
    """The PET of the ego against every other vehicle, one frame at a time (module docstring)."""

    def __init__(self):
        self.t = 0.0
        self.ego_cells = {}  # cell -> [last time, heading on entry]
        self.other_cells = {}  # cell -> {vehicle key: [last time, heading on entry]}
        self.min_pet = math.inf
        self.min_pet_t = None

    def _encroach(self, h, rec):
        if abs(wrap(h - rec[1])) > PET_MIN_ANGLE_RAD:
            pet = self.t - rec[0]
            if pet < self.min_pet:
                self.min_pet, self.min_pet_t = pet, self.t

    def observe(self, dt, vehicles):
        """One frame of ``dt`` s: ``vehicles`` is an iterable of (key, is_ego, (x, y) centre,
        heading rad, length m, width m), keys unique per vehicle over the episode."""
        self.t += dt
        t = self.t
        entries = []
        for key, ego, position, h, length, width in vehicles:
            for cell in footprint_cells(position, h, length, width):
                if ego:
                    rec = self.ego_cells.get(cell)
                else:
                    rec = self.other_cells.setdefault(cell, {}).get(key)
                if rec is None:
                    entries.append((ego, key, cell, h))
                else:
                    rec[0] = t
        # Entries last: a vehicle still in the cell has its time of this frame (PET 0).
        for ego, key, cell, h in entries:
            if ego:
                for rec in self.other_cells.get(cell, {}).values():
                    self._encroach(h, rec)
                self.ego_cells[cell] = [t, h]
            else:
                rec = self.ego_cells.get(cell)
                if rec is not None:
                    self._encroach(h, rec)
                self.other_cells[cell][key] = [t, h]
