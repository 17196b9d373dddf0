"""A LAMMPS run on one or several MPI ranks for tests/test_lammps_hook.py.

    mpiexec -n 2 python tests/lammps_ranks_worker.py OUT.npz

runs the scene of :func:`scene` with the Python hook and with the native contact (quantized),
both on the ranks given, moves the slab boundary twice between frames (``balance``: many atoms
and their contact states migrate at once) and keeps, per frame, what the backend yields plus
where the atoms are (which rank owns each tag, how many ghosts a rank holds, whether a rank's
atoms are out of tag order).  Rank 0 writes OUT.npz.
"""
from __future__ import annotations

import sys

import numpy as np

from mdgran.backends.lammps import LammpsBackend
from mdgran.model.scene import load_scene

#: frames after which the boundary between 2 ranks moves to this fraction of the box
BALANCE = {25: 0.3, 50: 0.7}


def scene():
    """micro-star's physics with 21 beads (23 atoms with the walls): the slab boundary of two
    ranks falls on the middle bead (bead 11, tag 12; rank 1 owns it at first), which is struck
    towards rank 0, so it moves there and its contacts snap off at the boundary; 6 events."""
    return load_scene("micro-star", [("chain.n", 21), ("impulse.bead", 11),
                                     ("impulse.velocity", -40.0), ("run.duration", 8.0)])


def collect(contact: str, balance: bool) -> dict:
    """Frames of one run as arrays, plus the placement of the atoms at every frame; ``balance``
    (several ranks only) moves the slab boundary at the frames of :data:`BALANCE`."""
    # LAMMPS's default skin (0.3) instead of chain.in's 32 p, tested at every step: atoms then
    # migrate as soon as they cross the slab boundary (within a frame), the case under test
    options = {"contact": contact,
               "extra_commands": ["neighbor 0.3 bin", "neigh_modify every 1 delay 0 check yes"]}
    if contact == "native":
        options["events"] = "quantized"
    b = LammpsBackend(scene(), **options)
    keys = ("x", "v", "closed", "d_visc", "d_hyst", "pe", "owner", "nghost", "unsorted")
    out = {k: [] for k in keys}
    events = []
    for k, fr in enumerate(b.frames()):
        out["x"].append(fr.x)
        out["v"].append(fr.v)
        out["closed"].append(fr.closed)
        out["d_visc"].append(fr.dissipated_viscous)
        out["d_hyst"].append(fr.dissipated_hysteresis)
        out["pe"].append(b.lmp.get_thermo("pe"))  # the contact energy: the only pe here
        events += [(e.time, e.contact, e.kind) for e in fr.events]
        owner, nghost, unsorted = placement(b.lmp)
        out["owner"].append(owner)
        out["nghost"].append(nghost)
        out["unsorted"].append(unsorted)
        if k in BALANCE:  # the backend's next run skips set-up ("pre no"): a run with set-up
            # rebuilds the ghosts.  Its set-up call recomputes this step's forces (with a(t) in
            # the damping estimate, where the backend's runs keep those of the step, with
            # a(t - dt)): the runs compared must all make it
            if balance:
                b.lmp.command(f"balance 1.0 x {BALANCE[k]}")
            b.lmp.command("run 0 post no")
    res = {k: np.array(v) for k, v in out.items()}
    res["events"] = np.array(events).reshape(-1, 3)
    return res


def placement(lmp):
    """(rank owning each tag, most ghosts on a rank, whether some rank's owned atoms are out of
    tag order); collective on several ranks."""
    nlocal = lmp.extract_setting("nlocal")
    nghost = lmp.extract_setting("nghost")
    tags = np.array(lmp.numpy.extract_atom("id", nelem=nlocal))
    mine = (lmp.extract_setting("world_rank"), tags, nghost)
    if lmp.extract_setting("world_size") > 1:
        parts = lmp.get_mpi_comm().allgather(mine)
    else:
        parts = [mine]
    owner = np.zeros(int(lmp.get_natoms()) + 1, dtype=int)
    for rank, t, _ in parts:
        owner[t] = rank
    return (owner, max(p[2] for p in parts),
            any(np.any(np.diff(p[1]) < 0) for p in parts))


def main(path):
    result = {}
    for contact in ("hook", "native"):
        for k, v in collect(contact, balance=True).items():
            result[f"{contact}_{k}"] = v
    from mdgran.simulation import mpi_rank

    if mpi_rank() == 0:
        np.savez(path, **result)


if __name__ == "__main__":
    main(sys.argv[1])
