"""The paper's measures as pure functions of a run's stored arrays (no plotting here).

Modules, one idea each (all nondimensional, bead mass 1, time in 1/q, energy in eta p):

* :mod:`.effective_damping`: ``C_eff(t) / C_+`` of Eq. 9 and its smoothing.
* :mod:`.clusters`: contact states, clusters, re-clustering, Appendix A segments.
* :mod:`.modes`: linearized modes of a cluster (Eq. 6 about its compressed state).
* :mod:`.wavelet`: Morlet wavelet spectrum of a bead's motion.
* :mod:`.maps`: spatio-temporal maps (kinetic energy, relative velocity, cluster boundaries).
* :mod:`.pulse`: primary pulse speed and the characteristic period ``T_c``.
* :mod:`.coincidence`: do C_eff peaks coincide with re-clustering-rate peaks?
* :mod:`.nulls`: null models of the Fig. 7 slope and selection-free alternatives.

:func:`run_summary` condenses a run into scalars for :mod:`mdgran.studies.sweep`.  The functions of
a whole run take a :class:`~mdgran.output.run_record.Run` (its scene, contact states and events come
with it); ``run.measures`` (:class:`~mdgran.output.measures.Measures`) computes each measure once.
"""
from __future__ import annotations

import math

import numpy as np

from .clusters import (MERGE_WITHIN, Cluster, ClusterHistory, ReclusteringAnalysis, Segments,
                       analyze_reclustering, cluster_history, clusters_of, contact_states,
                       new_clusters, reclustering_events, representative_segment,
                       segment_means, segments, smoothed_cumulative, trajectory_history)
from .coincidence import (coincidence_case, coincidence_fraction, coincidence_shift_test,
                          coincidence_test, peak_times, pooled_channel_coincidence,
                          pooled_coincidence_test, run_coincidence, shifted_fractions)
from .effective_damping import (CHANNELS, SMOOTHING_TIME, c_eff, channel_damping,
                                contact_damping, decay_time, dissipated_channels,
                                dissipated_energy, effective_damping, envelope_mean,
                                smoothed_kinetic, smoothing_effect, smoothing_spline)
from .maps import (boundary_map, cluster_labels, kinetic_energy_map, relative_velocity_map,
                   states_map)
from .nulls import (NullCase, case_of_run, fig7_points, fig7_slope, fig7_statistic,
                    max_mean, null_case, null_summary, random_late, random_late_null,
                    rate_damping_correlation, rate_damping_null, segment_statistic, swap_cases,
                    synthetic_case, time_shift)
from .modes import (cluster_modes, cluster_modes_in_run, equilibrium_modes, modes,
                    stiffness_matrix)
from .pulse import characteristic_period, primary_pulse_speed, pulse_duration
from .wavelet import default_omegas, morlet_cwt, peak_frequency, wavelet_spectrum


def run_summary(traj, *, smoothing_time: float = SMOOTHING_TIME,
                merge_within: float = MERGE_WITHIN, c_eff=None, reclustering=None) -> dict:
    """Scalars of one run (a :class:`~mdgran.output.run_record.Run`) for a sweep's case summary
    (undefined values are ``None``); ``c_eff``, ``reclustering``: the run's
    :func:`effective_damping` and :func:`analyze_reclustering` at the same settings, if already
    computed (:class:`~mdgran.output.measures.Measures` passes its own).

    * ``c_eff_max_segment``: largest segment-mean ``C_eff / C_+`` (the representative segment,
      Sec. VI; all segments but the last); ``c_eff_max_segment_rate``: that segment's
      re-clustering rate ``r_m`` (clusters per time unit); ``c_eff_max_segment_start``/``_end``.
    * ``c_eff_late_segment``, ``c_eff_late_segment_rate``, ``c_eff_late_segment_start``: the same
      with segments starting before ``T_c / 2`` (the primary pulse's first crossing of the
      chain) left out, so the impact transient cannot be the representative segment.
    * ``c_eff_mean``: time mean of ``C_eff / C_+`` over the run; ``c_eff_peak``: its maximum.
    * ``clusters_formed``: newly formed clusters over the run (cumulative count at the end).
    * ``reclustering_rate_mean``: ``clusters_formed`` divided by the time from the start to the
      last re-clustering event (the active part of the run).
    * ``last_reclustering_time``: time of the last re-clustering event.
    * ``kinetic_remaining``: mean kinetic energy over the last 10 % of the run over ``T(0)``.
    * ``kinetic_decay_time`` / ``kinetic_decay_time_10``: first time ``<<T>>`` falls below
      ``T(0)/e`` / ``0.1 T(0)``.
    * ``characteristic_period``: ``T_c = 2 (n+1) / c_pulse``.
    """
    t = traj.time
    if len(t) < 10:
        return {}
    kin = traj.ledger["kinetic_energy"]
    cbar = effective_damping(traj, smoothing_time=smoothing_time) if c_eff is None else c_eff
    rc = (analyze_reclustering(traj, cbar, smoothing_time=smoothing_time,
                               merge_within=merge_within)
          if reclustering is None else reclustering)
    rep = rc.representative
    tc = characteristic_period(traj)
    late = representative_segment(rc.segments, rc.segment_c_eff,
                                  0.5 * tc if np.isfinite(tc) else -np.inf)
    ev_t, _ = reclustering_events(rc.history, merge_within)
    formed = int(rc.history.cumulative[-1]) if len(rc.history.cumulative) else 0
    tail = t >= t[0] + 0.9 * (t[-1] - t[0])
    envelope = envelope_mean(t, kin)  # <<T>>, once for both decay times
    out = {
        "c_eff_max_segment": rc.segment_c_eff[rep] if rep >= 0 else None,
        "c_eff_max_segment_rate": rc.segment_rate[rep] if rep >= 0 else None,
        "c_eff_max_segment_start": rc.segments.start[rep] if rep >= 0 else None,
        "c_eff_max_segment_end": rc.segments.end[rep] if rep >= 0 else None,
        "c_eff_late_segment": rc.segment_c_eff[late] if late >= 0 else None,
        "c_eff_late_segment_rate": rc.segment_rate[late] if late >= 0 else None,
        "c_eff_late_segment_start": rc.segments.start[late] if late >= 0 else None,
        "c_eff_mean": np.sum(0.5 * (cbar[1:] + cbar[:-1]) * np.diff(t)) / (t[-1] - t[0]),
        "c_eff_peak": np.max(cbar),
        "clusters_formed": formed,
        "reclustering_rate_mean": formed / (ev_t[-1] - t[0]) if len(ev_t) else 0.0,
        "last_reclustering_time": ev_t[-1] if len(ev_t) else None,
        "kinetic_remaining": np.mean(kin[tail]) / kin[0] if kin[0] > 0 else None,
        "kinetic_decay_time": decay_time(t, kin, math.exp(-1.0), envelope=envelope),
        "kinetic_decay_time_10": decay_time(t, kin, 0.1, envelope=envelope),
        "characteristic_period": tc,
    }
    return {k: (None if v is None or not np.isfinite(v) else
                (int(v) if isinstance(v, (int, np.integer)) else float(v)))
            for k, v in out.items()}
