"""
The paper's Fig. 2 in miniature
===============================

Macro against micro: the same 20-bead chain at two scales, 2.5 mm beads with Hertz contact
(``macro-hertz``) and 2.5 um beads with adhesive Schwarz contact (``micro-star``), struck so
that their primary pulses travel at the same speed. In the macro chain the primary pulse
keeps crossing the chain whole; in the micro chain contacts snap open and shut, the pulse
breaks up and the chain splits into clusters that re-form. The paper's figure runs to
t = 400; this one to t = 150, on the reference backend as the paper's study does (about ten
seconds). Time is in characteristic periods ``T_c``, the pulse's time to cross the chain and
back.
"""
import matplotlib.pyplot as plt
import numpy as np

import mdgran
from mdgran import analysis

runs = {name: mdgran.run(name, "reference", set={"run.duration": 150.0}).trajectory
        for name in ("macro-hertz", "micro-star")}

# %%
# Kinetic energy per bead (normalized per instant by the largest), with the cluster
# boundaries of the micro chain (its open contacts) drawn in cyan; then the total kinetic
# energy and the effective damping ``C_eff / C_+`` of the paper's Eq. 9.
fig = plt.figure(figsize=(8, 7.5))
grid = fig.add_gridspec(3, 2)
for row, (name, run) in enumerate(runs.items()):
    ax = fig.add_subplot(grid[row, :])
    tc = run.measures.characteristic_period
    t = run.time / tc
    ax.imshow(analysis.kinetic_energy_map(run).T, aspect="auto", origin="lower",
              cmap="magma", extent=(t[0], t[-1], 0.5, run.n + 0.5),
              interpolation="nearest")
    if name == "micro-star":
        opened = analysis.boundary_map(run)
        for j, k in enumerate(run.contact_numbers):
            ax.plot(np.where(opened[:, j], t, np.nan), np.full(len(t), k - 0.5),
                    "c", lw=0.7)
    ax.set(ylabel="bead", title=f"({'ab'[row]}) {name}: kinetic energy per bead "
                                f"(T_c = {tc:.3g})")
ax_t, ax_c = fig.add_subplot(grid[2, 0]), fig.add_subplot(grid[2, 1])
for (name, run), color in zip(runs.items(), ("C0", "C3")):
    t = run.time / run.measures.characteristic_period
    e_imp = run.impulse_energy
    ax_t.plot(t, run.ledger["kinetic_energy"] / e_imp, color=color, lw=0.5, alpha=0.5)
    ax_t.plot(t, analysis.smoothed_kinetic(run) / e_imp, color=color, lw=1.6, label=name)
    ax_c.plot(t, run.measures.c_eff, color=color, lw=1.3, label=name)
ax_t.set(xlabel="time / T_c", ylabel="T / E_imp", title="(c) kinetic energy")
ax_c.set(xlabel="time / T_c", ylabel="C_eff / C_+", title="(d) effective damping")
ax_t.legend(fontsize=8)
ax_c.legend(fontsize=8)
fig.tight_layout()

# %%
# How much kinetic energy is left at the end, as a share of the impulse:
for name, run in runs.items():
    left = run.ledger["kinetic_energy"][-1] / run.impulse_energy
    print(f"{name:12s} T / E_imp at t = {run.time[-1]:.0f}: {left:.3f}; "
          f"{len(run.ev_time)} contact events")
