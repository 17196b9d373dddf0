"""Cross-check against LAMMPS's native granular models (no mdgran hook): the agreement numbers.

    python benchmarks/lammps_native.py

1. Force laws: LAMMPS ``jkr``, ``dmt`` and ``hertz/material`` against mdgran's laws at the
   mapped parameters (benchmarks/native_lammps.py), and where LAMMPS's jkr lets go.
2. JKR pair collisions (collision-pair scene, law jkr, snap_off "force") at impact speeds
   that bounce (3.0), bounce only under the force rule (2.0) and stick (1.2), at three dt,
   against the reference backend; the same LAMMPS runs against the reference with the
   displacement rule, to show which rule LAMMPS follows.
3. The Hertz chain (macro-hertz physics, 30 time units) at four dt, as is (damped) and with
   the damping off, plus the naive mapping (LAMMPS given the scene's E unchanged).
4. jkr-chain with the force rule (20 time units) at three dt.

Writes benchmarks/results/lammps_native.json.  About 30 s on one core.
"""
from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import numpy as np

from mdgran.backends.lammps.env import lammps_version
from mdgran.model.scene import load_scene
from mdgran.simulation import run

import native_lammps as nl  # benchmarks/native_lammps.py

PAIR_SPEEDS = (3.0, 2.0, 1.2)
PAIR_DTS = (2e-3, 1e-3, 5e-4)
CHAIN_DTS = (0.01, 0.005, 0.0025, 0.00125)
CHAIN_DURATION = 30.0


def force_laws() -> dict:
    out = {}
    jkr = load_scene("collision-pair", [("contact.law", "jkr"), ("contact.snap_off", "force")])
    law = jkr.law
    d = np.linspace(5.0, law.delta_off + 1e-9, 2000)
    f = nl.probe_force(jkr, d)
    off = law.delta_off
    probe = nl.probe_force(jkr, [1.0, off + 1e-7, off - 1e-7])
    m = nl.native_mapping(jkr)
    out["jkr"] = {
        "points": len(d), "delta_range": [float(d[-1]), float(d[0])],
        "max_abs_force_error": float(np.max(np.abs(f - law.force(d)))),
        "lammps_pulloff_distance_p": nl.lammps_pulloff_distance(m) / m.scales.p,
        "delta_force_max": law.delta_force_max,
        "delta_min_displacement_rule": law.delta_min,
        "closed_at_delta_off_plus_1e-7": bool(probe[1] != 0.0),
        "open_at_delta_off_minus_1e-7": bool(probe[2] == 0.0),
        "force_just_before_snap_off": float(probe[1]),
        "matches_snap_off_rule": "force",
    }
    dmt = load_scene("collision-pair", [("contact.law", "dmt")])
    d = np.linspace(5.0, -0.2, 500)
    fd = nl.probe_force(dmt, d)
    out["dmt"] = {"max_abs_force_error": float(np.max(np.abs(
        fd - np.where(d > 0, dmt.law.force(d), 0.0))))}
    hz = load_scene("macro-hertz")
    d = np.linspace(10.0, 0.0, 500)
    fh = nl.probe_force(hz, d)
    raw = nl.probe_force(hz, d[:-1], nl.native_mapping(hz, raw_modulus=True))
    out["hertz"] = {"max_abs_force_error": float(np.max(np.abs(fh - hz.law.force(d)))),
                    "max_rel_force_error": float(np.max(np.abs(fh[:-1] / hz.law.force(d[:-1])
                                                               - 1.0))),
                    "naive_mapping_force_ratio": float(np.mean(raw / hz.law.force(d[:-1])))}
    return out


def pair_collisions() -> list:
    rows = []
    for v0 in PAIR_SPEEDS:
        base = [("contact.law", "jkr"), ("impulse.velocity", v0)]
        sc = load_scene("collision-pair", base + [("contact.snap_off", "force")])
        sc_disp = load_scene("collision-pair", base + [("contact.snap_off", "displacement")])
        ref = run(sc, "reference").trajectory
        ref_disp = run(sc_disp, "reference").trajectory
        keep = ref_disp.ev_contact > 0
        disp = nl.pair_summary(ref_disp.time, ref_disp.x, ref_disp.v, ref_disp.ev_time[keep],
                               ref_disp.ev_kind[keep])
        law = sc.law
        row = {"v0": v0, "escape_speed_force_rule": nl.escape_speed(law),
               "escape_speed_displacement_rule": nl.escape_speed(sc_disp.law),
               "analytic_rebound_speed_force_rule": float(np.sqrt(max(
                   v0 * v0 - 4.0 * law.loop_energy, 0.0))),
               "reference_displacement_rule": disp, "runs": []}
        for dt in PAIR_DTS:
            r = nl.compare_pair(sc, dt, ref)
            ln = r["lammps"]
            r["rebound_speed_bound"] = nl.quantization_bound(law, v0, ln["rebound_speed"], dt) \
                if ln["separated"] else None
            r["same_outcome_as_displacement_rule"] = (ln["separated"] == disp["separated"])
            if ln["separated"] and disp["separated"]:
                r["rebound_speed_diff_vs_displacement_rule"] = abs(
                    ln["rebound_speed"] - disp["rebound_speed"])
            row["runs"].append(r)
            print(f"pair v0={v0} dt={dt}: separated {ln['separated']} (ref force "
                  f"{r['reference']['separated']}, ref displacement {disp['separated']}), "
                  f"rebound err {r.get('rebound_speed_error', float('nan')):.2e} (bound "
                  f"{r['rebound_speed_bound'] or float('nan'):.1e}), duration err "
                  f"{r.get('contact_duration_error', float('nan')):.2e}, x err "
                  f"{r['x_max_abs_error']:.2e}, v err {r['v_max_abs_error']:.2e}", flush=True)
        rows.append(row)
    return rows


def hertz_chain() -> dict:
    out = {}
    for label, extra in (("damped", []), ("undamped", [("contact.damping", 0.0)])):
        sc = load_scene("macro-hertz", [("run.duration", CHAIN_DURATION),
                                        ("run.tolerance", 1e-11)] + extra)
        ref = run(sc, "reference").trajectory
        rows = []
        for dt in CHAIN_DTS:
            r = nl.compare_chain(sc, dt, CHAIN_DURATION, ref)
            rows.append(r)
            print(f"hertz {label} dt={dt}: x err {r['x_max_abs_error']:.2e}, "
                  f"v err {r['v_max_abs_error']:.2e}", flush=True)
        errs = [r["x_max_abs_error"] for r in rows]
        orders = [float(np.log2(a / b)) for a, b in zip(errs, errs[1:])]
        out[label] = {"runs": rows, "observed_orders": orders}
        if label == "damped":  # the hook backend on the same window, for context
            out["hook_backend_damped"] = []
            for dt in CHAIN_DTS[1:]:
                tr = run(sc.with_overrides([("run.dt", dt)]), "lammps").trajectory
                out["hook_backend_damped"].append(
                    {"dt": dt, "x_max_abs_error": float(np.max(np.abs(tr.x - ref.x)))})
        if label == "damped":
            out["naive_mapping"] = nl.compare_chain(
                sc, CHAIN_DTS[-1], CHAIN_DURATION, ref, nl.native_mapping(sc, raw_modulus=True))
            out["mapping"] = nl.native_mapping(sc).as_dict()
    return out


def jkr_chain() -> dict:
    """jkr-chain (20 beads, walls, tethers, damping) with the force rule: every contact starts
    closed at delta = 0, which LAMMPS's touch history is primed for (see NativeChain)."""
    sc = load_scene("jkr-chain", [("run.duration", 20.0), ("contact.snap_off", "force"),
                                  ("run.tolerance", 1e-10)])
    ref = run(sc, "reference").trajectory
    rows = [nl.compare_chain(sc, dt, 20.0, ref) for dt in (0.0025, 0.00125, 0.000625)]
    for r in rows:
        print(f"jkr-chain dt={r['dt']}: x err {r['x_max_abs_error']:.2e}", flush=True)
    return {"reference_events": int(len(ref.ev_time)), "runs": rows}


def main():
    t0 = time.perf_counter()
    result = {"lammps_version": lammps_version(), "python": platform.python_version(),
              "jkr_mapping": nl.native_mapping(load_scene(
                  "collision-pair", [("contact.law", "jkr"),
                                     ("contact.snap_off", "force")])).as_dict(),
              "force_laws": force_laws()}
    print(json.dumps(result["force_laws"], indent=1), flush=True)
    result["jkr_pair"] = pair_collisions()
    result["hertz_chain"] = hertz_chain()
    result["jkr_chain_force_rule"] = jkr_chain()
    result["wall_time_s"] = time.perf_counter() - t0
    out = Path(__file__).parent / "results" / "lammps_native.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {out} ({result['wall_time_s']:.1f} s)")


if __name__ == "__main__":
    main()
