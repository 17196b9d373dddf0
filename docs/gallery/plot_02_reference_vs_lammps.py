"""
The reference against LAMMPS
============================

The same scene on two independent implementations: the event-driven reference integrator,
and LAMMPS with mdgran's native contact (``lammps:native``, a C++ fix compiled as a LAMMPS
plugin, which locates each snap event inside its step). A short run of micro-star: up to the
predictability horizon of the chain the two trajectories agree to the fixed-step
integrator's error.
"""
import matplotlib.pyplot as plt
import numpy as np

import mdgran

keys = {"run.duration": 40.0}
ref = mdgran.run("micro-star", "reference", set=keys).trajectory
lmp = mdgran.run("micro-star", "lammps:native", set=keys).trajectory
print(f"reference: {len(ref.ev_time)} events; "
      f"LAMMPS (native contact): {len(lmp.ev_time)}")

# %%
# Displacements of a few beads (units of p) from both, and the largest difference over the
# beads against time.
fig, (ax, diff) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
for i, color in zip((0, 4, 9, 19), ("C0", "C1", "C2", "C3")):
    ax.plot(ref.time, ref.x[:, i], color=color, lw=1.6, label=f"bead {i + 1}")
    ax.plot(lmp.time, lmp.x[:, i], color="k", lw=0.7, ls="--")
ax.set(ylabel="x (p)", title="reference (colour) and LAMMPS native (dashed)")
ax.legend(fontsize=8, ncols=4)
gap = np.max(np.abs(ref.x - lmp.x), axis=1)
diff.semilogy(ref.time, np.maximum(gap, 1e-16), lw=0.9)
diff.set(xlabel="t (1/q)", ylabel="max |x_ref - x_lammps| (p)", ylim=(1e-8, 1e-2))
fig.tight_layout()

# %%
# ``mdgran compare`` does this systematically: each backend also runs refined to estimate
# its own error, trajectories are judged up to the horizon where those estimates reach
# 0.01 p, and the energy bookkeeping over the whole run.
for name, run in (("reference", ref), ("lammps:native", lmp)):
    print(f"{name:14s} ledger error {run.max_ledger_error:.2g} of E_imp")
