"""
Reading a run with h5py and with MDAnalysis
===========================================

A run's file is H5MD: any HDF5 reader opens it. This example writes a short run, reads its
displacements and energy with ``h5py``, then opens the same file with MDAnalysis's H5MD
reader and checks that both see the same bead positions.

The file keeps mdgran's own 1-D ``/particles/chain`` group, and a ``/particles/beads`` group
with the standard 3-D ``position`` (hard links, not copies) that generic readers take. With a
``[material]`` (micro-star has one) positions are in nm and times in ps, so MDAnalysis
converts them to its own units (Angstrom and ps).
"""
import tempfile
from pathlib import Path

import h5py
import matplotlib.pyplot as plt
import numpy as np

import mdgran

tmp = tempfile.TemporaryDirectory()
path = Path(tmp.name) / "run.h5"
res = mdgran.run("micro-star", "reference", out=path, set={"run.duration": 60.0})

# %%
# With h5py
# ---------
# Displacements ``[frames, beads]`` in units of p, their times, the total energy and the
# events; the layout is in the manual's *Output files* page.
with h5py.File(path, "r") as f:
    t = f["particles/chain/displacement/time"][()]
    x = f["particles/chain/displacement/value"][()]
    energy = f["observables/total_energy/value"][()]
    snapoffs = f["events/time"][()][f["events/kind"][()] == 0]
    position_nm = f["particles/beads/position/value"][()]       # [frames, beads, 3]
    print("status:", f["parameters"].attrs["status"], "| position unit:",
          f["particles/beads/position/value"].attrs["unit"])
print(f"{x.shape[0]} frames of {x.shape[1]} beads; "
      f"energy drift {np.ptp(energy) / abs(energy[0]):.1e} of |E0|")
print(f"{len(snapoffs)} snap-offs, the first at t = {np.round(snapoffs[:4], 2)}")

# %%
# With MDAnalysis
# ---------------
# MDAnalysis has no topology reader for H5MD, so a Universe is built empty with the right
# number of atoms and the file loaded as its trajectory. Each frame's ``positions`` are the
# beads' places in Angstrom; the file's observables come along in ``ts.data``.
import MDAnalysis as mda

with h5py.File(path, "r") as f:
    n = f["particles/beads/position/value"].shape[1]
    has_units = "unit" in f["particles/beads/position/value"].attrs
u = mda.Universe.empty(n, trajectory=True)
u.load_new(str(path), format="H5MD", convert_units=has_units)

times_ps, along_A, kinetic = [], [], []
for ts in u.trajectory:
    times_ps.append(ts.time)
    along_A.append(ts.positions[:, 0].copy())
    kinetic.append(ts.data["kinetic_energy"])
along_A = np.array(along_A)
gap = np.max(np.abs(along_A / 10.0 - position_nm[:, :, 0]))   # A -> nm
print(f"MDAnalysis read {len(u.trajectory)} frames of {u.atoms.n_atoms} atoms")
print(f"largest difference from h5py: {gap:.1e} nm (MDAnalysis reads float32)")

# %%
# The two readings, one over the other: the first beads' places (h5py: displacement in p;
# MDAnalysis: position in Angstrom less the initial place), and the kinetic energy from
# ``ts.data``.
scales = mdgran.read(path).scene.scales          # the material's SI scales
fig, (ax, ke) = plt.subplots(1, 2, figsize=(9, 3.6))
for i in range(3):
    ax.plot(t, x[:, i], lw=2, label=f"bead {i + 1} (h5py, p)")
    ax.plot(t, (along_A[:, i] - along_A[0, i]) * 1e-10 / scales.p_m, "k--", lw=0.8)
ax.set(xlabel="t (1/q)", ylabel="displacement (p)",
       title="h5py (colour), MDAnalysis (dashed)")
ax.legend(fontsize=7)
ke.plot(np.array(times_ps) * 1e-12 / scales.time_unit_s, kinetic, lw=1)
ke.set(xlabel="t (1/q)", ylabel="kinetic energy (eta p)",
       title="ts.data['kinetic_energy']")
fig.tight_layout()
tmp.cleanup()
