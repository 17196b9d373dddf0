"""A run's measures, each computed once (MDAnalysis's results container, for one run).

``run.measures`` (a :class:`Measures` of a :class:`~mdgran.output.run_record.Run`) computes the
paper's measures of the run on first use, at the default settings of :mod:`mdgran.analysis`, and
keeps them: ``C_eff / C_+`` (Eq. 9), the re-clustering analysis of Appendix A (clusters, segments,
smoothed rate), the coincidence test of their peaks, the dissipation channels, the case of the
null models and the sweep's scalar summary.  Each is computed from the ones before it, so a
report that asks for all of them computes ``C_eff`` and the clusters once per run.  Other
settings (another smoothing time, another window) are the pure functions of
:mod:`mdgran.analysis`, called directly.  Units as in :mod:`mdgran.analysis` (nondimensional).
"""
from __future__ import annotations

from functools import cached_property

from .. import analysis as an


class Measures:
    """The cached measures of one run (see the module docstring); ``computed`` lists the names
    computed so far, in order."""

    def __init__(self, run):
        self.run = run
        self.computed = []

    def _note(self, name: str):
        self.computed.append(name)

    @cached_property
    def c_eff(self):
        """``C_eff(t) / C_+`` [F] (:func:`~mdgran.analysis.effective_damping`)."""
        self._note("c_eff")
        return an.effective_damping(self.run)

    @cached_property
    def history(self):
        """The clusters after each event time (:func:`~mdgran.analysis.trajectory_history`)."""
        self._note("history")
        return an.trajectory_history(self.run)

    @cached_property
    def reclustering(self):
        """Clusters, segments, smoothed re-clustering rate, segment means
        (:func:`~mdgran.analysis.analyze_reclustering` with :attr:`c_eff` and
        :attr:`history`)."""
        self._note("reclustering")
        return an.analyze_reclustering(self.run, self.c_eff, history=self.history)

    @property
    def rate(self):
        """The smoothed re-clustering rate [F] (clusters per time unit)."""
        return self.reclustering.rate

    @cached_property
    def characteristic_period(self) -> float:
        """``T_c = 2 (n + 1) / c_pulse`` (:func:`~mdgran.analysis.characteristic_period`)."""
        self._note("characteristic_period")
        return an.characteristic_period(self.run)

    @cached_property
    def coincidence(self) -> dict:
        """Coincidence of the C_eff peaks with the rate peaks, window ``T_c``
        (:func:`~mdgran.analysis.run_coincidence`)."""
        self._note("coincidence")
        return an.run_coincidence(self.run, c_eff=self.c_eff, reclustering=self.reclustering)

    @cached_property
    def channels(self) -> dict:
        """``C_eff / C_+`` per dissipation channel, ``{"total", "viscous", "hysteresis"}``
        (:func:`~mdgran.analysis.channel_damping`)."""
        self._note("channels")
        return an.channel_damping(self.run, total=self.c_eff)

    @cached_property
    def null_case(self):
        """The run as the null models of Fig. 7 see it (:func:`~mdgran.analysis.case_of_run`)."""
        self._note("null_case")
        return an.case_of_run(self.run, self.c_eff, reclustering=self.reclustering)

    @cached_property
    def summary(self) -> dict:
        """The sweep's scalars of the run (:func:`~mdgran.analysis.run_summary`)."""
        self._note("summary")
        return an.run_summary(self.run, c_eff=self.c_eff, reclustering=self.reclustering)
