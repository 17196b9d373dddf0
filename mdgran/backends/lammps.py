"""The LAMMPS backend: the same scenes run in LAMMPS (``lammps_inputs/chain.in``).

LAMMPS integrates with velocity Verlet (``fix nve``) at ``run.dt``; the linear substrate is a
``fix spring/self`` tether; the contact (law, hysteresis, unilateral damping, and the cubic
substrate term when the scene has one) is a Python callback of ``fix external pf/callback``:

* **Contacts by tag.**  Contact ``k`` joins atoms with tags ``k`` and ``k + 1``.  Positions and
  velocities of every atom the rank sees (owned and ghost) are scattered into arrays indexed by
  tag, so LAMMPS's re-sorting and migration of atoms do not matter.  Each contact's open/closed
  state is kept per contact, on every rank, for the whole chain: the ghost cut-off spans the
  chain's box (see ``ghostcut``), so every rank updates every contact from identical positions,
  and the states agree across ranks by construction.
* **Hysteresis, step-quantized.**  At each step a closed contact with ``delta <= delta_off``
  opens (its energy ``V(delta)`` goes to ``D_hysteresis``) and an open one with ``delta >= 0``
  closes (strict inequalities where ``delta_off = 0``, DMT and Hertz, so a contact resting at
  ``delta = 0`` does not flip).  The event time is recorded by linear interpolation of
  ``delta`` within the step; the dynamics switch at the step.  This quantization makes the
  method first order in ``dt`` through events (see docs/lammps.md).
* **Half-step velocities.**  ``post_force`` sees ``v(t + dt/2)``; the damping force uses
  ``v(t + dt) ~ v(t + dt/2) + dt/2 a(t)`` (``a`` from the previous step), which keeps the
  damping term second order.  At step 0 the velocities are the initial (full-step) ones.
* The callback writes every component of the force array (LAMMPS does not zero it), and
  recomputes without advancing any state when called twice for the same step (the set-up
  call of a ``run``).  The contact energy is handed to LAMMPS with
  ``fix_external_set_energy_global``, so ``thermo`` shows it (``f_contact``).
* **Force evaluation** from :class:`mdgran.contact.ContactTable` (4001 nodes uniform in
  ``sqrt(delta - delta_min)``, cubic spline in that variable; 2e-12 absolute force error), written
  as a LAMMPS-style table file next to the run; ``contact_eval = "exact"`` uses the Newton
  inversion instead.  A compression beyond the table's ``delta_max`` stops the run.
* **Native contact** (``contact="native"``): the same contact as ``fix mdgran/chain`` of the
  C++ plugin ``mdgranplugin.so`` (:mod:`mdgran.native_plugin`), in place of the hook: same law
  (the same spline coefficients, handed over in a file), same switching rule, same operations,
  so the two agree to round-off (measured bitwise); the contact then costs ~20-27 ns per
  bead-step instead of ~155-190 (benchmarks/bench_lammps_plugin.py).  Events,
  ``D_hysteresis`` and ``D_viscous`` are read back from the fix; its per-contact states are
  per-atom data that migrate with the atoms, and with MPI each rank updates the contacts of its
  own atoms.
"""
from __future__ import annotations

import time as _time
from pathlib import Path

import numpy as np

from .. import native_plugin
from ..contact import ContactTable
from ..lammps_env import LammpsUnavailable, check_available, new_lammps
from ..scene import SceneError
from ..signals import deferred
from .base import CLOSE, OPEN, Backend, Event, Frame, IntegrationError

INPUT = Path(__file__).resolve().parents[2] / "lammps_inputs" / "chain.in"


def input_file() -> Path:
    """``lammps_inputs/chain.in`` of the checkout, or the copy installed with the package."""
    if INPUT.exists():
        return INPUT
    return Path(__file__).resolve().parents[1] / "lammps_inputs" / "chain.in"


class LammpsBackend(Backend):
    """Velocity Verlet in LAMMPS at ``run.dt`` with the contact as a Python hook."""

    name = "lammps"
    order = 1  # step-quantized snap events: first order in dt (second order between events)
    accepted_options = ("comm", "contact_eval", "table_points", "table_file", "extra_commands",
                        "dt", "contact")
    #: ledger bound ``C dt`` per unit of the energy scale (Backend.ledger_model): measured C
    #: (ledger error / E_s / dt) up to 1.0 (hard/jkr-force to t = 400 at dt = 0.01; 0.88 at
    #: dt = 0.0025), micro-star 0.42 (dt = 0.0025) and 0.17 (0.01), the other hard cases
    #: 0.01-0.51 at dt = 0.01: 4x margin (3x at dt = 0.01, where the cap binds)
    ledger_c = {1: 4.0}

    def __init__(self, scene, comm=None, contact_eval="table", table_points=4001,
                 table_file=None, extra_commands=(), contact="hook", **options):
        check_available()  # LammpsUnavailable (an ImportError): one line, before anything runs
        if contact not in ("hook", "native"):
            raise SceneError("contact", f"must be 'hook' or 'native', not {contact!r}")
        self.contact = contact
        self.plugin = None
        if contact == "native":
            try:  # the plugin built for this LAMMPS (built now if only a compiler is there)
                self.plugin = native_plugin.plugin_path()
            except native_plugin.PluginUnavailable as exc:
                raise LammpsUnavailable(f"native LAMMPS contact unavailable: {exc}") from None
        super().__init__(scene, **options)
        self.extra_commands = list(extra_commands)
        run = scene.data["run"]
        self.dt = float(options.get("dt", run["dt"]))
        interval = float(run["output_interval"])
        self.steps_per_frame = int(round(interval / self.dt))
        if abs(self.steps_per_frame * self.dt - interval) > 1e-9 * interval:
            raise SceneError("run.dt", f"must divide run.output_interval = {interval} "
                             f"(dt = {self.dt})")
        self.comm = comm
        m = self.model
        self.law = m.law
        self.table = ContactTable(m.law, table_points) if contact_eval == "table" else None
        self.table_file = table_file
        self.walls = m.walls
        self.n = m.n
        self.ntot = m.n + 2 if m.walls else m.n
        method = ("Python contact hook" if contact == "hook"
                  else "native contact (fix mdgran/chain)")
        self.stats = {"method": f"LAMMPS velocity Verlet + {method}",
                      "dt": self.dt, "steps": 0, "events": 0, "contact_eval": contact_eval,
                      "wall_time_s": 0.0, "callback_s": 0.0}
        if self.table is not None:
            self.stats["table"] = self.table.error()
        strict = self.law.delta_off == 0.0
        self._open_if = (lambda d: d < 0.0) if strict else (lambda d: d <= self.law.delta_off)
        self._close_if = (lambda d: d > 0.0) if strict else (lambda d: d >= 0.0)

    # ---- set-up ------------------------------------------------------------------------
    def _start(self):
        try:
            lmp = new_lammps(comm=self.comm)
        except LammpsUnavailable as exc:
            raise IntegrationError(str(exc)) from None
        d = self.scene.data
        bead = int(d["impulse"]["bead"])
        struck = bead + 1 if self.walls else bead
        spacing = 1.0 / self.ntot
        delta_max = self.table.delta_max if self.table is not None else 100.0
        ghost = 2.0 * delta_max + 2.0
        variables = {"ntot": self.ntot, "spacing": repr(spacing), "walls": int(self.walls),
                     "k1": repr(float(self.model.k1)), "struck": struck,
                     "v0": repr(float(d["impulse"]["velocity"])), "dt": repr(self.dt),
                     "ghostcut": repr(ghost), "thermo_every": max(1, self.steps_per_frame)}
        for k, v in variables.items():
            lmp.command(f"variable {k} equal {v}")
        lmp.file(str(input_file()))
        for cmd in self.extra_commands:  # e.g. "atom_modify sort 1 0.5" in the tests
            lmp.command(cmd)
        self.lmp = lmp
        self.spacing = spacing
        # initial places by tag, as LAMMPS placed them: the lattice spacing it derives from
        # the density differs from 1/ntot in the last bits, which would put every contact at
        # delta = +-1e-17 instead of 0 (and open Hertz and DMT contacts at t = 0)
        x_init = np.ctypeslib.as_array(lmp.gather_atoms("x", 1, 3)).reshape(-1, 3)[:, 0]
        self.x0 = np.concatenate([[0.0], x_init])  # index = tag
        nc = self.model.n_contacts
        self.closed = np.ones(nc, dtype=bool) if self.model.gap <= 0 else np.zeros(nc, bool)
        self.d_visc = 0.0
        self.d_hyst = 0.0
        self.events = []
        self._last_step = None
        self._acc_prev = None  # total acceleration by tag at the previous step
        self._power_prev = 0.0
        self._delta_prev = None
        self._error = None
        self.rank = lmp.extract_setting("world_rank")
        if self.contact == "native":
            self._start_native(lmp)
            return
        lmp.set_fix_external_callback("contact", self._callback, None)
        if self.table_file is not None and self.table is not None and self.rank == 0:
            self.table.write_lammps(self.table_file)

    def _start_native(self, lmp):
        """Replace ``fix external`` by ``fix mdgran/chain`` (appended after the other fixes:
        the x force is then ``(0 - k1 u) + F`` instead of ``(0 + F) - k1 u``, the same number)."""
        import tempfile

        m, law = self.model, self.law
        args = ["law hertz" if law.kind == "hertz" else f"law schwarz fc {law.fc!r}",
                f"snap_off {law.snap_off}", f"damping {float(m.damping)!r}",
                f"k1 {float(m.k1)!r}", f"k3 {float(m.k3)!r}", f"gap {float(m.gap)!r}",
                f"walls {'yes' if self.walls else 'no'}",
                f"closed {'yes' if m.gap <= 0 else 'no'}"]
        if self.table is not None:  # every rank writes its own copy (no shared file system)
            self._tmpdir = tempfile.TemporaryDirectory(prefix="mdgran-spline-")
            path = Path(self._tmpdir.name) / "contact.spline"
            native_plugin.write_spline(self.table, path)
            args.append(f"table {path}")
        for cmd in ("unfix contact", *native_plugin.load_commands(self.plugin),
                    "fix contact all mdgran/chain " + " ".join(args),
                    "fix_modify contact energy yes"):
            lmp.command(cmd)
        self._events_read = 0
        if self.table_file is not None and self.table is not None and self.rank == 0:
            self.table.write_lammps(self.table_file)

    def _read_native(self):
        """Dissipation, new events and contact states from fix mdgran/chain (synced over ranks at
        the end of every run)."""
        lmp = self.lmp
        self.d_hyst = lmp.extract_fix("contact", 0, 1, 0)  # LMP_STYLE_GLOBAL, LMP_TYPE_VECTOR
        self.d_visc = lmp.extract_fix("contact", 0, 1, 1)
        n = int(lmp.extract_fix("contact", 0, 1, 2))
        for row in range(self._events_read, n):  # LMP_TYPE_ARRAY: time, contact, kind, step
            t, num, kind = (lmp.extract_fix("contact", 0, 2, row, c) for c in range(3))
            self.events.append(Event(t, int(num), CLOSE if kind == 1.0 else OPEN))
        self.stats["events"] += n - self._events_read
        self._events_read = n
        self.stats["steps"] = int(lmp.extract_global("ntimestep"))
        # per-atom vector by tag: the state of the contact to the atom's right
        state = np.ctypeslib.as_array(lmp.gather("f_contact", 1, 1))
        self.closed = state[:self.model.n_contacts] != 0.0

    # ---- the contact hook ---------------------------------------------------------------
    def _by_tag(self, nlocal):
        lmp = self.lmp
        nall = nlocal + lmp.extract_setting("nghost")
        tags = lmp.numpy.extract_atom("id", nelem=nall)
        x = lmp.numpy.extract_atom("x", nelem=nall, dim=3)
        v = lmp.numpy.extract_atom("v", nelem=nall, dim=3)
        X = np.empty(self.ntot + 1)
        V = np.empty(self.ntot + 1)
        X[tags] = x[:, 0]
        V[tags] = v[:, 0]
        return X - self.x0, V  # displacement by tag; velocity by tag

    def _contact_geometry(self, disp, vel):
        """Compression and its rate per contact, contract order (from tag arrays)."""
        if self.walls:  # contact k joins tag k and k+1; walls are tags 1 and ntot (x = 0)
            u = disp[1:].copy()
            u[0] = u[-1] = 0.0
            w = vel[1:].copy()
            w[0] = w[-1] = 0.0
        else:
            u, w = disp[1:], vel[1:]
        delta = u[:-1] - u[1:]
        if self.model.gap:
            delta = delta - self.model.gap
        return delta, w[:-1] - w[1:], u, w

    def _callback(self, caller, step, nlocal, tag, x, f):
        """Exceptions cannot cross LAMMPS's C frames: the first one is kept and re-raised by
        :meth:`frames` after the current chunk (the forces of the failing step are zeroed)."""
        if self._error is not None:
            f[:, :] = 0.0
            return
        try:
            self._contact_hook(step, nlocal, tag, f)
        except Exception as exc:  # noqa: BLE001 - re-raised outside the C call
            self._error = exc
            f[:, :] = 0.0

    def _contact_hook(self, step, nlocal, tag, f):
        t0 = _time.perf_counter()
        disp, vel = self._by_tag(nlocal)
        delta, rate, u, w = self._contact_geometry(disp, vel)
        new_step = step != self._last_step
        dt = self.dt
        if step > 0 and self._acc_prev is not None:
            # v(t+dt) ~ v(t+dt/2) + dt/2 a(t): second order in the damping force
            w_est = w + 0.5 * dt * self._acc_prev
            rate = w_est[:-1] - w_est[1:]
        if new_step:
            self._update_states(step, delta)
        closed = self.closed
        fc = self.table.force(delta) if self.table is not None else self.law.force(delta)
        fc = np.where(closed, fc, 0.0)
        c = self.model.damping
        if c:
            fc = fc + np.where(closed, c * rate, 0.0)
        acc = np.zeros(len(u))
        acc[:-1] -= fc  # contact k pushes its right bead (+) and its left bead (-)
        acc[1:] += fc
        if self.walls:
            acc[0] = acc[-1] = 0.0
        ext = acc.copy()
        if self.model.k3:
            ext -= self.model.k3 * u**3
        if self.model.k1:
            acc_total = ext - self.model.k1 * u
        else:
            acc_total = ext
        if not np.all(np.isfinite(ext)):
            bad = int(np.flatnonzero(~np.isfinite(ext))[0])
            raise IntegrationError(f"non-finite force at t = {step * dt:.12g}, bead "
                                   f"{bad if self.walls else bad + 1}")
        if self.table is not None:
            over = delta > self.table.delta_max
            if np.any(over):
                k = int(np.flatnonzero(over)[0])
                raise IntegrationError(
                    f"compression {delta[k]:.4g} beyond the contact table (delta_max = "
                    f"{self.table.delta_max:g}) at t = {step * dt:.12g}, contact "
                    f"{self.model.contact_numbers[k]}")
        # tag-ordered acceleration (index tag-1) -> local rows
        f[:, :] = 0.0
        f[:, 0] = ext[tag - 1]
        if new_step:
            power = c * float(np.sum(np.where(closed, rate * rate, 0.0))) if c else 0.0
            if self._last_step is not None:
                self.d_visc += 0.5 * (power + self._power_prev) * dt
            self._power_prev = power
            self._acc_prev = acc_total
            self._last_step = step
            self.stats["steps"] = int(step)
        energy = float(np.sum(np.where(closed, self.law.energy(delta), 0.0)))
        self.lmp.fix_external_set_energy_global("contact", energy if self.rank == 0 else 0.0)
        self.stats["callback_s"] += _time.perf_counter() - t0

    def _update_states(self, step, delta):
        closed = self.closed
        opening = closed & self._open_if(delta)
        closing = ~closed & self._close_if(delta)
        if not (opening.any() or closing.any()):
            self._delta_prev = delta
            return
        nums = self.model.contact_numbers
        t = step * self.dt
        prev = self._delta_prev if self._delta_prev is not None else delta
        for k in np.flatnonzero(opening | closing):
            thr = self.law.delta_off if opening[k] else 0.0
            span = prev[k] - delta[k]
            frac = (prev[k] - thr) / span if span != 0.0 else 1.0
            te = t - self.dt + min(max(frac, 0.0), 1.0) * self.dt if step > 0 else t
            if opening[k]:
                self.d_hyst += float(self.law.energy(delta[k]))
                self.events.append(Event(te, int(nums[k]), OPEN))
            else:
                self.events.append(Event(te, int(nums[k]), CLOSE))
        closed[opening] = False
        closed[closing] = True
        self.stats["events"] += int(opening.sum() + closing.sum())
        self._delta_prev = delta

    # ---- frames ------------------------------------------------------------------------
    def _gather(self):
        lmp = self.lmp
        x = np.ctypeslib.as_array(lmp.gather_atoms("x", 1, 3)).reshape(-1, 3)[:, 0]
        v = np.ctypeslib.as_array(lmp.gather_atoms("v", 1, 3)).reshape(-1, 3)[:, 0]
        disp = x - self.x0[1:]
        if self.walls:
            return disp[1:-1].copy(), v[1:-1].copy()
        return disp.copy(), v.copy()

    def _frame(self, k, t):
        if self.contact == "native":
            self._read_native()
        x, v = self._gather()
        fr = Frame(step=k, time=float(t), x=x, v=v, closed=self.closed.copy(),
                   dissipated_viscous=self.d_visc, dissipated_hysteresis=self.d_hyst,
                   events=list(self.events))
        self.events = []
        return fr

    def _advance(self, command):
        """Run a LAMMPS command; SIGINT and SIGTERM are held until it returns (an exception
        raised inside the Python contact callback would be dropped by ctypes and the run would
        go on: :func:`mdgran.signals.deferred`)."""
        try:
            with deferred():
                self.lmp.command(command)
        except Exception as exc:  # noqa: BLE001 - LAMMPS errors arrive as plain exceptions
            step = self._last_step if self.contact == "hook" else \
                self.lmp.extract_global("ntimestep")
            raise IntegrationError(f"LAMMPS stopped at step {step}: "
                                   f"{str(exc).splitlines()[0]}") from None
        if self._error is not None:
            if isinstance(self._error, IntegrationError):
                raise self._error
            raise IntegrationError(f"contact hook failed at t = "
                                   f"{(self._last_step or 0) * self.dt:.12g}: {self._error!r}")

    def frames(self, resume=None):
        if resume is not None:
            raise IntegrationError("the LAMMPS backend cannot resume from a checkpoint")
        wall0 = _time.perf_counter()
        self._start()
        lmp = self.lmp
        try:
            out_times = self.output_times()
            self._advance("run 0 post no")  # set-up: the callback sees the initial state
            yield self._frame(0, 0.0)
            for k in range(1, len(out_times)):
                self._advance(f"run {self.steps_per_frame} pre no post no")
                yield self._frame(k, out_times[k])
        finally:
            self.stats["wall_time_s"] = _time.perf_counter() - wall0
            lmp.close()
