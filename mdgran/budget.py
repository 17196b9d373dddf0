"""Term budget: how much each force term of Eq. 6 mattered in a run.

For each term (contact law, unilateral damping, linear substrate ``k1 x``, cubic substrate
``k3 x^3``): the largest force it exerted on any bead at any stored frame (units of eta), that
force relative to the largest of all terms, and its largest energy (units of eta p) relative to
the impulse energy: stored energy for conservative terms, the dissipated total for damping.

A term the scene switches off is reported as ``off``; for the cubic substrate of a scene with a
``[material]``, the budget also gives what the paper's wire (Table II: L_s = 2.5 d, d_s = 0.4 d,
E_s = 400 GPa) *would* have contributed, which is how the paper's neglect of it is checked.
"""
from __future__ import annotations

import numpy as np

from .model.chain import model_from_scene


def paper_wire_k3(scene) -> float | None:
    """Nondimensional cubic coefficient of the paper's wire for this scene's K1 (None without a
    material)."""
    sc = scene.scales
    if sc is None:
        return None
    from .model.units import wire_cubic, wire_tension

    d = sc.diameter
    k1_si = float(scene.substrate.k1) * sc.stiffness
    length = 2.5 * d
    k3_si = wire_cubic(400e9, 0.4 * d, wire_tension(k1_si, length), length)
    return k3_si * sc.p**2 / sc.stiffness


def term_budget(run) -> dict:
    """The budget of :class:`~mdgran.output.run_record.Run` ``run`` (module docstring), from its
    stored frames and contact states."""
    scene = run.scene
    m = model_from_scene(scene)
    e_imp = scene.energy_scale or 1.0
    closed = run.closed
    x, v = run.x, run.v
    f_law = np.zeros(len(run.time))
    f_damp = np.zeros(len(run.time))
    for k in range(len(run.time)):
        delta = m.compressions(x[k])
        fl = np.where(closed[k], m.law.force(delta), 0.0)
        f_law[k] = np.abs(m._apply(fl)).max()
        if m.damping:
            fd = np.where(closed[k], m.damping * m.differences(v[k]), 0.0)
            f_damp[k] = np.abs(m._apply(fd)).max()
    xmax = np.abs(x).max()
    k3 = m.k3 if m.k3 else paper_wire_k3(scene)
    terms = {
        "contact": {"on": True, "max_force": float(f_law.max()),
                    "max_energy": float(np.abs(run.ledger["contact_energy"]).max())},
        "damping": {"on": bool(m.damping), "max_force": float(f_damp.max()),
                    "max_energy": float(run.ledger["dissipated_viscous"][-1])},
        "substrate_linear": {"on": bool(m.k1), "max_force": float(m.k1 * xmax),
                             "max_energy": float(0.5 * m.k1 * np.max(np.sum(x * x, axis=1)))},
        "substrate_cubic": {"on": bool(m.k3), "k3": k3,
                            "max_force": float((k3 or 0.0) * xmax**3),
                            "max_energy": float(0.25 * (k3 or 0.0)
                                                * np.max(np.sum(x**4, axis=1)))},
    }
    if not m.k3:
        terms["substrate_cubic"]["note"] = ("off; values are what the paper's wire would add"
                                            if k3 else "off")
    biggest = max(t["max_force"] for t in terms.values() if t["on"]) or 1.0
    for t in terms.values():
        t["force_share"] = t["max_force"] / biggest
        t["energy_share"] = t["max_energy"] / e_imp
    return terms


def format_budget(terms: dict) -> str:
    lines = [f"{'term':<18}{'on':<5}{'max force (eta)':>16}{'share':>10}{'energy/E_imp':>14}"]
    for name, t in terms.items():
        lines.append(f"{name:<18}{'yes' if t['on'] else 'off':<5}{t['max_force']:>16.4g}"
                     f"{t['force_share']:>10.3g}{t['energy_share']:>14.3g}"
                     + (f"   ({t['note']})" if t.get("note") else ""))
    return "\n".join(lines)
