"""
A long chain
============

A pulse in a chain of 100,000 beads on the fast backend. Beyond the pulse every bead is at
rest, and the fast backend steps only the beads in motion (its activity front), so the run
costs what the pulse reaches, not the chain's length. No file is written: a reporter,
:class:`~mdgran.studies.long_chain.PulseTracker`, keeps per bead its largest speed and when it was
reached, as the frames go by.
"""
import time

import matplotlib.pyplot as plt
import numpy as np

import mdgran
from mdgran.model.chain import model_from_scene
from mdgran.studies.long_chain import PulseTracker, pulse_profile

n, v0 = 100_000, 12.0
scene = mdgran.load_scene("micro-star", [("chain.n", n), ("impulse.velocity", v0),
                                          ("run.duration", 100.0)])
tracker = PulseTracker(n)
start = time.perf_counter()
res = mdgran.run(scene, "fast", keep=False, reporters=[tracker])
wall = time.perf_counter() - start
profile = pulse_profile(tracker, model_from_scene(scene), v0)
share = res.stats["bead_steps"] / (n * res.stats["steps"])
print(f"{n} beads to t = 100: {wall:.2f} s (with compiling, on a first run), "
      f"{res.status}")
print(f"bead-steps taken: {share:.2%} of N x steps")
print(f"reach {profile['reach']} beads, "
      f"speed {profile['speed_beads_per_time']:.2f} beads per 1/q")
print(f"{profile['snapoffs_total']} snap-offs, "
      f"{profile['open_contacts']} contacts left open")

# %%
# The pulse's largest speed on each bead (units of v0) and when it passed: it runs at a
# nearly constant speed while snap-offs and damping take its energy. By t = 100 it has
# reached the bead printed above as its reach (speed at least 1e-3 v0); a few beads further
# on barely stir, and beyond them the rest of the chain has not moved, nor been stepped.
reach = profile["reach"]
beads = np.arange(1, n + 1)
show = slice(0, reach + 20)
peak = profile["peak_v"][show] / v0
fig, (amp, when) = plt.subplots(1, 2, figsize=(9, 3.6))
amp.semilogy(beads[show], np.where(peak > 0, peak, np.nan), lw=1)
amp.axvline(reach, color="C3", ls="--", lw=1, label=f"reach: {reach} beads")
amp.set(xlabel="bead", ylabel="largest |v| / v0", title="pulse amplitude",
        ylim=(1e-4, 2))
amp.legend(fontsize=8)
when.plot(beads[show], profile["peak_t"][show], ".", ms=2)
when.set(xlabel="bead", ylabel="time of largest |v| (1/q)", title="pulse arrival")
fig.tight_layout()
