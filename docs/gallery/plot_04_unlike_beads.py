"""
Unlike beads and a striker
==========================

Beads need not be alike: ``[beads]`` gives each its own diameter, density, modulus and
adhesion as ratios to the reference bead, and each contact then follows its pair's law;
``[striker]`` makes bead 1 a free bead of its own size launched into the chain instead of an
ideal impulse. Two built-in scenes: ``mixed/dimer`` (every second bead 0.6 times as large,
so 0.216 times as heavy) and ``mixed/striker`` (a bead twice the diameter, 8 times the mass,
launched at v0 = 4 into a free chain of 19).
"""
import matplotlib.pyplot as plt
import numpy as np

import mdgran
from mdgran import analysis

runs = {name: mdgran.run(name, "reference", set={"run.duration": 100.0}).trajectory
        for name in ("mixed/dimer", "mixed/striker")}
for name, run in runs.items():
    print(f"{name:14s} masses {np.round(run.scene.mixture.mass[:4], 3)} ...: "
          f"{len(run.ev_time)} events, {run.status}")

# %%
# Kinetic energy per bead against time (each bead's ``m_i v_i^2 / 2``, normalized per instant
# by the largest), with each chain's bead sizes drawn to scale on the left.
fig, axes = plt.subplots(2, 2, figsize=(8, 6), width_ratios=[1, 12], sharey="row")
for (name, run), (beads, ax) in zip(runs.items(), axes):
    size = np.cbrt(run.scene.mixture.mass)  # diameter ratio at equal density
    beads.scatter(np.zeros(run.n), np.arange(1, run.n + 1), s=60 * size**2,
                  color="0.4")
    beads.set(xticks=[], ylabel="bead", xlim=(-1, 1))
    ax.imshow(analysis.kinetic_energy_map(run).T, aspect="auto", origin="lower",
              cmap="magma", extent=(run.time[0], run.time[-1], 0.5, run.n + 0.5),
              interpolation="nearest")
    ax.set(title=f"{name}: kinetic energy per bead", xlabel="t (1/q)")
fig.tight_layout()

# %%
# In the dimer chain the light beads rattle between their heavy neighbours and the pulse
# spreads; the heavy striker pushes the whole chain and, on this run, never lets go of bead
# 2. Where the energy went (units of the impulse energy):
for name, run in runs.items():
    led = {k: v[-1] / run.impulse_energy for k, v in run.ledger.items()}
    print(f"{name:14s} kinetic {led['kinetic_energy']:.3f}, "
          f"lost to damping {led['dissipated_viscous']:.3f}, "
          f"to snap-offs {led['dissipated_hysteresis']:.3f}")
