"""The LAMMPS backend: the same scenes run in LAMMPS (``mdgran/backends/lammps/chain.in``).

LAMMPS integrates with velocity Verlet (``fix nve``) at ``run.dt``; the contact (law,
hysteresis, unilateral damping) and the substrate (``chain.in``'s ``fix spring/self`` tether
is replaced by the hook's ``-k1 u``, the same force and cheaper, and the cubic term when the
scene has one) are a Python callback of ``fix external pf/callback`` whose inner loop is
compiled (:mod:`mdgran.backends.lammps.hook`, numba):

* **A decomposable chain.**  The beads lie on a line ``spacing`` apart (128 p: above any
  compression the contact table allows, so neighbours never pass each other) and LAMMPS splits
  the line over the MPI ranks (``processors * 1 1``) with a ghost cut-off of 2.5 spacings:
  each rank holds its own beads and a few ghosts at each end, not the whole chain.
* **Contacts by tag, per rank.**  Contact ``k`` joins atoms with tags ``k`` and ``k + 1``
  (found through a tag -> local index map, so LAMMPS's sorting and migration of atoms do not
  matter).  Each rank evaluates only the contacts of its own atoms: those whose left atom it
  owns, and those whose right atom it owns with a ghost left atom; a contact straddling two
  ranks is updated on both from identical positions, so it switches identically.
* **State per atom.**  The open/closed state of contact ``k``, its previous compression, the
  atom's initial x and its previous acceleration are per-atom properties of atom ``k`` (``fix
  property/atom ... ghost yes``): they migrate with the atom between ranks.  The previous
  accelerations of the atoms next to a rank boundary are exchanged every step (one
  ``MPI_Allgather`` through mpi4py: the damping rate of a straddling contact needs them on
  both sides).  Each event is recorded once,
  by the owner of the contact's left atom; events, ``D_hysteresis`` and ``D_viscous`` are
  gathered over the ranks after each ``run`` (at every frame).
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
  call of a ``run``).  The contact energy (exact law, summed over the ranks) is handed to LAMMPS
  with ``fix_external_set_energy_global`` at thermo steps, so ``thermo`` shows it
  (``f_contact``).
* **Force evaluation** from :class:`mdgran.model.contact.ContactTable` (4001 nodes uniform in
  ``sqrt(delta - delta_min)``, cubic spline in that variable; 2e-12 absolute force error), written
  as a LAMMPS-style table file next to the run; ``contact_eval = "exact"`` uses the Newton
  inversion instead.  A compression beyond the table's ``delta_max`` stops the run.
* **Native contact** (``contact="native"``): the same contact as ``fix mdgran/chain`` of the
  C++ plugin ``mdgranplugin.so`` (:mod:`mdgran.backends.lammps.plugin`), in place of the hook:
  same law (the same spline coefficients, handed over in a file), same switching rule, same
  operations in the same order as the compiled hook, so the two agree bitwise on 1 and 2 ranks
  (tests/test_lammps_plugin.py, tests/test_lammps_hook.py).  Events, ``D_hysteresis`` and
  ``D_viscous`` are read back from the fix; its per-contact states are per-atom data that
  migrate with the atoms, and with MPI each rank updates the contacts of its own atoms.
* **Unlike beads, strikers, substrate damping, thermal velocities**: the hook's
  :class:`~mdgran.backends.lammps.hook.HookMix` and the fix's ``mixture FILE`` and
  ``sub_damping C`` give each contact its pair's law ``A f(delta / L)`` and each bead its mass
  and substrate factor; LAMMPS's integrator gets the masses as per-atom masses (``fix
  property/atom rmass``); every rank sets its atoms' initial displacements (the equilibrium of
  unlike beads between walls) and velocities (thermal plus impulse) from
  :meth:`ChainModel.initial_state` (:meth:`LammpsBackend._initial_state`).  The homogeneous
  chain takes none of these branches.
* **Force pulses and base motions** (``[pulse]``, ``[base]``, :mod:`mdgran.model.drive`): evaluated
  at the time LAMMPS's velocity Verlet evaluates the step's forces, the end of its position
  update ``t = step dt`` (located: each pass's end); the substrate acts on ``u - u_b`` and
  ``w - u_b'``, the pulse pushes its bead.  Their work ``W`` is integrated by the trapezoidal
  rule of its rate between step ends, per rank, summed like ``D_viscous``, and is each frame's
  ``external_work``: the hook's driven step (:func:`~mdgran.backends.lammps.hook.get_step`,
  ``_account``, ``_sync_hook``), the fix's ``pulse`` and ``base`` keywords (its vector's 4th
  element).  Undriven scenes take none of this.
* **Located events** (``events="located"``, the default with the native contact): the fix
  integrates the chain itself (``fix move`` and ``fix substrate`` go) and steps each event's
  window of beads alone inside the step, as the fast backend does: second order in dt through
  snap events (``order = 2``; docs/lammps.md); on several ranks the ghost cut-off is
  :data:`LOCATED_GHOST_SPACINGS`.  ``events="quantized"``: the hook's step-quantized
  switching, bitwise the hook's run.
"""
from __future__ import annotations

import contextlib
import ctypes
import math
import time as _time
from pathlib import Path

import numpy as np

from ...model.chain import first_contact
from ...model.contact import ContactTable
from .env import LammpsUnavailable, check_available, new_lammps
from ...model.scene import SceneError
from ...signals import deferred
from . import plugin as native_plugin
from ..base import (ALL_FEATURES, CLOSE, OPEN, Backend, Event, Events, Frame, Frames,
                   IntegrationError, check_excitation_steps, steps_per_frame)

#: the LAMMPS input the backend starts from (package data: in the checkout and in the wheel)
INPUT = Path(__file__).resolve().parent / "chain.in"
#: ghost cut-off in bead spacings: a closed contact's partner lies within 1 spacing + 1 p
GHOST_SPACINGS = 2.5
#: ... and with located events on several ranks: each rank steps the event windows that write
#: its beads, and needs the beads within 3 of a window (fix mdgran/chain's WINDOW_MARGIN): with
#: 8.5 spacings a window of up to 5 beads next to a slab boundary (a snap-off's is 2)
LOCATED_GHOST_SPACINGS = 8.5
#: (tag, acceleration) pairs a rank sends in the one collective of a step (_share_aprev)
SHARE_SLOTS = 8
#: ledger bound C dt**2 of the located native mode (Backend.ledger_model), per unit of E_s:
#: measured C (ledger error / E_s / dt**2) at the scenes' dt over their whole runs 0.42-3.0
#: (micro-star 1.85, macro-hertz 1.51, jkr/dmt-chain 1.9, hard/* 1.2-2.0, hard/violent-50
#: 3.0), the fast backend's to 3 digits (the same method): its bound, 5x over 3.0
LEDGER_C_LOCATED = 15.0


def _event_mode(events, contact):
    """``events`` option: "located" (default with the native contact: second order through
    snap events) or "quantized" (switch at step ends; the only mode of the Python hook)."""
    if events is None:
        return "located" if contact == "native" else "quantized"
    if events not in ("located", "quantized"):
        raise SceneError("events", f"must be 'located' or 'quantized', not {events!r}")
    if events == "located" and contact != "native":
        raise SceneError("events", "'located' needs contact='native' (the Python hook switches "
                         "contacts at step ends: events='quantized')")
    return events


class _AtomViews:
    """numpy views of LAMMPS's per-atom arrays for the hook, made anew only when LAMMPS has
    reallocated an array (its address changed): making one costs ~25 us (profiled)."""

    def __init__(self, lmp):
        self.names = ((b"id", lmp.c_tagint, 1), (b"x", ctypes.c_double, 3),
                      (b"v", ctypes.c_double, 3), (b"d_x0", ctypes.c_double, 1),
                      (b"i_closed", ctypes.c_int32, 1), (b"d_dprev", ctypes.c_double, 1),
                      (b"d_aprev", ctypes.c_double, 1))
        self.handle = lmp.lmp
        proto = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.c_void_p, ctypes.c_char_p)
        self.extract = proto(("lammps_extract_atom", lmp.lib))  # raw address, own restype
        self.cache = {}

    def view(self, key, address, ctype, nelem, dim):
        """``[nelem]`` or ``[nelem, dim]`` array at ``address`` (the data block)."""
        hit = self.cache.get(key)
        if hit is None or hit[0] != (address, nelem):
            arr = np.ctypeslib.as_array((ctype * (nelem * dim)).from_address(address))
            hit = ((address, nelem), arr.reshape(nelem, dim) if dim > 1 else arr)
            self.cache[key] = hit
        return hit[1]

    def atoms(self, nmax, nall):
        """Tags, x, v and the hook's properties of the owned and ghost atoms."""
        out = []
        for name, ctype, dim in self.names:
            address = self.extract(self.handle, name)
            if dim > 1:  # double **: the rows point into one block
                address = ctypes.c_void_p.from_address(address).value
            out.append(self.view(name, address, ctype, nmax, dim)[:nall])
        return out

    def rows(self, ptr, nrows, key):
        """``[nrows, 3]`` doubles of a ``double **`` handed over by LAMMPS (fix external's f)."""
        address = ctypes.cast(ptr[0], ctypes.c_void_p).value if nrows else None
        if address is None:
            return np.zeros((0, 3))
        return self.view(key, address, ctypes.c_double, nrows, 3)


class LammpsBackend(Backend):
    """Velocity Verlet in LAMMPS at ``run.dt`` with the contact as a Python hook."""

    name = "lammps"
    order = 1  # step-quantized snap events: first order in dt (second order between events)
    accepted_options = ("comm", "contact_eval", "table_points", "table_file", "extra_commands",
                        "dt", "contact", "events")
    #: ledger bound ``C dt`` per unit of the energy scale (Backend.ledger_model): measured C
    #: (ledger error / E_s / dt) up to 1.0 (hard/jkr-force to t = 400 at dt = 0.01; 0.88 at
    #: dt = 0.0025), micro-star 0.42 (dt = 0.0025) and 0.17 (0.01), the other hard cases
    #: 0.01-0.51 at dt = 0.01: 4x margin (3x at dt = 0.01, where the cap binds)
    ledger_c = {1: 4.0, 2: LEDGER_C_LOCATED}
    #: unlike beads, strikers, thermal velocities, substrate damping, force pulses and base
    #: motions: hook and native contact
    supports = ALL_FEATURES

    def __init__(self, scene, comm=None, contact_eval="table", table_points=4001,
                 table_file=None, extra_commands=(), contact="hook", events=None, **options):
        check_available()  # LammpsUnavailable (an ImportError): one line, before anything runs
        if contact not in ("hook", "native"):
            raise SceneError("contact", f"must be 'hook' or 'native', not {contact!r}")
        self.contact = contact
        self.event_mode = _event_mode(events, contact)
        if self.event_mode == "located":
            self.order = 2  # events located inside the step by fix mdgran/chain
        self.plugin = None
        if contact == "native":
            try:  # the plugin built for this LAMMPS (built now if only a compiler is there)
                self.plugin = native_plugin.plugin_path()
            except native_plugin.PluginUnavailable as exc:
                raise LammpsUnavailable(f"native LAMMPS contact unavailable: {exc}") from None
        super().__init__(scene, **options)
        self._check_law_tables(contact_eval)
        self.extra_commands = list(extra_commands)
        run = scene.run
        self.dt = float(options.get("dt", run.dt))
        self.steps_per_frame = steps_per_frame(self.dt, float(run.output_interval))
        check_excitation_steps(self.model, self.dt, self.name)
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
        verlet = ("velocity Verlet with located events by" if self.event_mode == "located"
                  else "velocity Verlet +")
        self.stats = {"method": f"LAMMPS {verlet} {method}", "event_mode": self.event_mode,
                      "dt": self.dt, "steps": 0, "events": 0, "contact_eval": contact_eval,
                      "wall_time_s": 0.0, "callback_s": 0.0}
        if self.table is not None:
            self.stats["table"] = self.table.error()

    def _check_law_tables(self, contact_eval):
        """Unlike beads with one law per pair (random diameters with ``contact.lambda``) would
        need a force table per contact (128 KB each, in the hook and in the plugin's files):
        more than the fast backend's limit is refused, before anything runs."""
        from ..fast import MAX_LAW_TABLES

        mix = self.model.mixture
        if mix is not None and contact_eval == "table" and len(mix.laws) > MAX_LAW_TABLES:
            raise SceneError("beads", f"{len(mix.laws)} distinct pair laws (each pair's lambda "
                             "follows its size): the LAMMPS backend tabulates at most "
                             f"{MAX_LAW_TABLES}; run it with the exact law "
                             "('lammps:contact_eval=exact'), or give contact.fc (one law)")

    # ---- set-up ------------------------------------------------------------------------
    def _start(self):
        try:
            lmp = new_lammps(comm=self.comm)
        except LammpsUnavailable as exc:
            raise IntegrationError(str(exc)) from None
        bead = int(self.scene.impulse.bead)
        struck = bead + 1 if self.walls else bead
        spacing = self.bead_spacing()
        variables = {"ntot": self.ntot, "spacing": repr(spacing), "walls": int(self.walls),
                     "k1": repr(float(self.model.k1)), "struck": struck,
                     "v0": repr(float(self.scene.impulse.velocity)), "dt": repr(self.dt),
                     "ghostcut": repr(spacing * (LOCATED_GHOST_SPACINGS
                                                 if self.event_mode == "located"
                                                 else GHOST_SPACINGS)),
                     "thermo_every": max(1, self.steps_per_frame)}
        for k, v in variables.items():
            lmp.command(f"variable {k} equal {v}")
        lmp.file(str(INPUT))
        for cmd in self.extra_commands:  # e.g. "atom_modify sort 1 0.5" in the tests
            lmp.command(cmd)
        self.lmp = lmp
        self.spacing = spacing
        # initial places by tag, as LAMMPS placed them (displacements are x - x0)
        x_init = np.ctypeslib.as_array(lmp.gather_atoms("x", 1, 3)).reshape(-1, 3)[:, 0]
        if not np.all(np.diff(x_init) > 0.0):
            raise IntegrationError("LAMMPS did not number the beads along the line (tags must "
                                   "increase with x)")
        self.x0 = np.concatenate([[0.0], x_init])  # index = tag
        nc = self.model.n_contacts
        self.closed = np.ones(nc, dtype=bool) if self.model.gap <= 0 else np.zeros(nc, bool)
        self.d_visc = 0.0
        self.d_hyst = 0.0
        self.work = 0.0  # external_work: the force pulse's and the base motion's
        self.events = []
        self._last_step = None
        self._error = None
        self.rank = lmp.extract_setting("world_rank")
        self.nprocs = lmp.extract_setting("world_size")
        if self.contact == "native":
            self._start_native(lmp)
            return
        self._start_hook(lmp)
        if self.table_file is not None and self.table is not None and self.rank == 0:
            self.table.write_lammps(self.table_file)

    def bead_spacing(self) -> float:
        """Distance between neighbouring beads on LAMMPS's line (units p): the power of two
        above the largest compression the contact table allows plus the initial gap, so that
        neighbours never pass each other (``delta_max = 100``: 128)."""
        delta_max = self.table.delta_max if self.table is not None else 100.0
        if self.model.mixed:  # each table reaches delta_max in its contact's own units
            delta_max = delta_max * float(np.max(self.model.mixture.length_scale))
        return 2.0 ** math.ceil(math.log2(delta_max + max(float(self.model.gap), 0.0) + 1.0))

    def _start_native(self, lmp):
        """Replace ``fix external`` by ``fix mdgran/chain``.  Quantized events: the fix applies
        the linear substrate in place of ``fix substrate`` (spring/self), with that fix's
        stiffness (``tether``, :func:`lammps_hook.tether_stiffness`), the force the hook applies,
        and moves the chain with ``fix move``'s velocity Verlet in its place (``integrate
        yes``): bitwise the hook's run, two loops over the atoms fewer per step.  Located
        events: the fix integrates the chain and applies the linear substrate itself, so
        ``fix move`` (nve) and ``fix substrate`` go."""
        import tempfile

        # every rank writes its own copies (no shared file system)
        self._tmpdir = tempfile.TemporaryDirectory(prefix="mdgran-spline-")
        args = self._native_model_args(Path(self._tmpdir.name))
        setup = ["unfix contact", *native_plugin.load_commands(self.plugin)]
        mode_args, unfixes = self._native_mode(lmp)
        for cmd in (*setup, *unfixes, "fix contact all mdgran/chain " + " ".join(args + mode_args),
                    "fix_modify contact energy yes"):
            lmp.command(cmd)
        self._events_read = 0
        self._read_events = native_plugin.event_reader(self.plugin)  # the fix's events
        self._initial_state(lmp)  # thermal velocities (the fix reads v at its set-up)
        if self.table_file is not None and self.table is not None and self.rank == 0:
            self.table.write_lammps(self.table_file)

    def _native_model_args(self, folder: Path) -> list:
        """The arguments of ``fix mdgran/chain`` that state the chain's physics: the law, its
        damping and substrate, walls and gap, and the files it reads (written into
        ``folder``): the force table, unlike beads, the excitations."""
        m, law = self.model, self.law
        args = ["law hertz" if law.kind == "hertz" else f"law schwarz fc {law.fc!r}",
                f"snap_off {law.snap_off}", f"damping {float(m.damping)!r}",
                f"k1 {float(m.k1)!r}", f"k3 {float(m.k3)!r}", f"gap {float(m.gap)!r}",
                f"walls {'yes' if self.walls else 'no'}",
                f"closed {'yes' if m.gap <= 0 else 'no'}"]
        if self.table is not None:
            path = folder / "contact.spline"
            native_plugin.write_spline(self.table, path)
            args.append(f"table {path}")
        if m.mixed:
            points = self.table.n if self.table is not None else None
            args.append(f"mixture {native_plugin.write_mixture(m, folder, points)}")
        if m.substrate_damping:
            args.append(f"sub_damping {float(m.substrate_damping)!r}")
        if m.drive is not None and m.drive.pulse is not None:  # tag = bead + 1 (+ 1: walls)
            p = m.drive.pulse
            args.append(f"pulse {p.bead + (2 if self.walls else 1)} {float(p.amplitude)!r} "
                        f"{float(p.duration)!r} {float(p.start)!r}")
        if m.drive is not None and m.drive.base is not None:
            args.append(f"base {native_plugin.write_base(m.drive.base, folder / 'base.txt')}")
        return args

    def _native_mode(self, lmp) -> tuple:
        """``(arguments, unfix commands)`` of the event mode: located, the fix integrates and
        owns the substrate (``fix move`` and ``fix substrate`` go); quantized, it applies the
        tether's force and does fix nve's work in their place."""
        from .hook import tether_stiffness

        if self.event_mode == "located":
            return ["events located"], [f"unfix {fix}" for fix in ("move", "substrate")
                                        if lmp.has_id("fix", fix)]
        args, unfixes = [], []
        if lmp.has_id("fix", "substrate"):
            args.append(f"tether {tether_stiffness(self.model.k1)!r}")
            unfixes.append("unfix substrate")
        if lmp.has_id("fix", "move"):
            args.append("integrate yes")
            unfixes.append("unfix move")
        return args, unfixes

    def _read_native(self):
        """Dissipation, new events and contact states from fix mdgran/chain (synced over ranks at
        the end of every run)."""
        self._read_native_sums()
        # per-atom vector by tag: the state of the contact to the atom's right
        state = np.ctypeslib.as_array(self.lmp.gather("f_contact", 1, 1))
        self.closed = state[:self.model.n_contacts] != 0.0

    def _read_native_sums(self):
        """Dissipation, external work, new events and the step count from fix mdgran/chain."""
        lmp = self.lmp
        self.d_hyst = lmp.extract_fix("contact", 0, 1, 0)  # LMP_STYLE_GLOBAL, LMP_TYPE_VECTOR
        self.d_visc = lmp.extract_fix("contact", 0, 1, 1)
        if self.model.drive is not None:
            self.work = lmp.extract_fix("contact", 0, 1, 3)
        n = int(lmp.extract_fix("contact", 0, 1, 2))
        if n > self._events_read:
            self.events = Events.join((self.events, self._native_events(self._events_read, n)))
        self.stats["events"] += n - self._events_read
        self._events_read = n
        self.stats["steps"] = int(lmp.extract_global("ntimestep"))
        if self.event_mode == "located":  # atoms the fix stepped (its activity front)
            self.stats["bead_steps"] = int(lmp.extract_fix("contact", 0, 1, 6))
            self.stats["event_windows_joined"] = int(lmp.extract_fix("contact", 0, 1, 7))

    # ---- the contact hook ---------------------------------------------------------------
    def _start_hook(self, lmp):
        """Per-atom state of the hook (``fix property/atom``: it migrates with the atoms, and
        LAMMPS copies it to ghost atoms when it builds them), the compiled kernel's parameters
        and, on several ranks, the communicator."""
        from . import hook as lammps_hook
        from ..fast_kernel import plain

        tether = lmp.has_id("fix", "substrate")  # the kernel applies its force instead
        if tether:
            lmp.command("unfix substrate")
        lmp.command("fix state all property/atom i_closed d_dprev d_aprev d_x0 ghost yes")
        n = lmp.extract_setting("nlocal")
        ex = lmp.numpy.extract_atom
        tag = ex("id", nelem=n)
        ex("d_x0", nelem=n)[:] = ex("x", nelem=n, dim=3)[:, 0]
        ex("i_closed", nelem=n)[:] = (tag < self.ntot) & (self.model.gap <= 0)
        ex("d_dprev", nelem=n)[:] = 0.0
        ex("d_aprev", nelem=n)[:] = 0.0
        self._kernel = lammps_hook
        params = lammps_hook.hook_parameters(self.model, self.law, self.table, self.dt, tether)
        self._flags = params.flags
        self._ntags = params.chain.ntags
        self._params = plain(params)  # crosses into compiled code as plain tuples
        self._step = lammps_hook.get_step(self._flags)
        self._initial_state(lmp)
        self._tmap = np.zeros(self.ntot + 2, dtype=np.int32)  # tag -> local index (checked)
        self._nmax = 0
        self._list_key = None  # (nlocal, nall, nmax, nbuild) of the kept contact list
        self._power_prev = 0.0
        self._work_prev = 0.0  # the excitations' power at the last step (driven scenes)
        # D_hysteresis, D_viscous, external work of this rank since the last sync
        self._part = np.zeros(3)
        self._events_part = []  # (step, left tag, kind, time) of this rank since the last sync
        self._thermo_every = max(1, self.steps_per_frame)
        self._mpi = None
        if self.nprocs > 1:
            try:
                self._mpi = lmp.get_mpi_comm()
            except Exception as exc:  # noqa: BLE001 - ImportError, or a LAMMPS without MPI
                raise IntegrationError(
                    f"the Python contact hook on {self.nprocs} MPI ranks needs mpi4py, a "
                    f"dependency of mdgran (pip install mpi4py), or use contact='native' "
                    f"({exc})") from None
        self._views = _AtomViews(lmp)
        # the raw callback: lammps.set_fix_external_callback would wrap tag, x and f into new
        # numpy arrays at every call (measured with the 7 arrays of _AtomViews also wrapped at
        # every call: 190 us per call under a load of 3; now 28 us under a load of 1)
        self._cfunc = lmp.FIX_EXTERNAL_CALLBACK_FUNC(self._callback)
        lmp.lib.lammps_set_fix_external_callback(lmp.lmp, b"contact", self._cfunc, None)

    def _initial_state(self, lmp):
        """Beyond the paper's start (unlike beads, initial random velocities): every owned
        atom's mass (``fix property/atom rmass``: per-atom masses, which ``fix nve`` then
        uses), displacement and velocity, by tag, from :meth:`ChainModel.initial_state` (the
        static equilibrium of unlike beads between walls, the thermal velocities plus the
        impulse): the same start as the reference and fast backends.  Called after ``d_x0``
        holds the atoms' places on the line; the homogeneous chain is left as chain.in made it."""
        m = self.model
        if not (m.mixed or m.temperature):
            return
        imp = self.scene.impulse
        x_start, v_start, _ = m.initial_state(int(imp.bead), float(imp.velocity))
        first = 2 if self.walls else 1  # tag of bead 0
        n = lmp.extract_setting("nlocal")
        ex = lmp.numpy.extract_atom
        bead = ex("id", nelem=n).astype(np.int64) - first
        mobile = (bead >= 0) & (bead < m.n)
        if m.mixed and not m.mixture.uniform_mass:
            lmp.command("fix masses all property/atom rmass")
            n = lmp.extract_setting("nlocal")
            rmass = ex("rmass", nelem=n)
            rmass[:] = 1.0
            rmass[mobile] = m.mixture.mass[bead[mobile]]
        x, v = ex("x", nelem=n, dim=3), ex("v", nelem=n, dim=3)
        x[mobile, 0] += x_start[bead[mobile]]
        v[mobile, 0] = v_start[bead[mobile]]

    def _buffers(self, nmax):
        """Scratch of the kernel, sized to LAMMPS's per-atom arrays (``nmax``)."""
        if nmax != self._nmax:
            self._u, self._w, self._fcon = np.empty(nmax), np.empty(nmax), np.empty(nmax)
            self._left = np.empty(nmax, dtype=np.int32)
            self._pairs = np.empty((nmax, 2), dtype=np.int32)
            self._edge = np.empty(2 * nmax, dtype=np.int64)
            self._ev = np.empty((nmax, 4))  # pages touched only by the rows written
            self._nmax = nmax
            self._scratch = (self._tmap, self._u, self._w, self._fcon, self._left, self._pairs,
                             self._ev)  # lammps_hook.Scratch, plain

    def _callback(self, caller, step, nlocal, tag_ptr, x_ptr, f_ptr):
        """Exceptions cannot cross LAMMPS's C frames: the first one is kept and re-raised by
        :meth:`frames` after the current chunk (the forces of this rank are zeroed from then
        on; its collective calls go on, so that the other ranks finish the chunk too)."""
        f = self._views.rows(f_ptr, nlocal, "fexternal")
        try:
            self._contact_hook(step, nlocal, f)
        except Exception as exc:  # noqa: BLE001 - re-raised outside the C call
            if self._error is None:
                self._error = exc
            f[:, :] = 0.0

    def _contact_hook(self, step, nlocal, f):
        t0 = _time.perf_counter()
        kernel, lmp = self._kernel, self.lmp
        nall = nlocal + lmp.extract_setting("nghost")
        nmax = lmp.extract_setting("nmax")
        self._buffers(nmax)
        tag, x, v, x0, closed, dprev, aprev = self._views.atoms(nmax, nall)
        atoms = (tag, x, v, f, x0, closed, dprev, aprev, nlocal, nall)  # lammps_hook.Atoms
        new_step = step != self._last_step
        # the map and the contact list, kept while the atoms' local indices hold: until LAMMPS
        # re-neighbours (its count of neighbour-list builds, thermo keyword nbuild, moves) or
        # sets up a run (a call for the step already done; the count restarts at 0 there)
        key = (nlocal, nall, nmax, self.lmp.get_thermo("nbuild"))
        if not new_step or key != self._list_key:
            self._list = kernel.contact_list(atoms, self._scratch, self._ntags)
            self._list_key = key
        if self._mpi is not None:  # collective: every rank, every call
            self._share_aprev(tag, nlocal, nall, aprev)
        npair, nown, missing = self._list
        if self._error is None:
            try:
                if missing >= 0:
                    raise self._kernel_error(kernel.PARTNER_MISSING, int(tag[missing]), 0.0,
                                             step)
                now = (step, new_step, self._last_step is not None, npair, nown)  # Now
                nev, power, ext_power, err, where, value = self._step(atoms, self._scratch, now,
                                                                      self._params)
                if err != kernel.OK:
                    raise self._kernel_error(err, int(tag[where]), value, step)
                if new_step:
                    self._account(step, tag, nev, power, ext_power)
            except Exception as exc:  # noqa: BLE001 - kept, raised after the chunk
                self._error = exc
        if self._error is not None:
            f[:, :] = 0.0
        if step % self._thermo_every == 0:  # contact energy for thermo (pe, f_contact)
            e = 0.0 if self._error is not None else kernel.contact_energy(
                atoms, self._scratch, self._params)
            if self._mpi is not None:
                e = self._mpi.allreduce(e)
            self.lmp.fix_external_set_energy_global("contact", e)
        self.stats["callback_s"] += _time.perf_counter() - t0

    def _share_aprev(self, tag, nlocal, nall, aprev):
        """Previous accelerations of the atoms next to a rank boundary to the ranks that hold
        them as ghosts (collective): the damping rate of a contact straddling two ranks uses
        the accelerations of both its atoms on both ranks.  One ``MPI_Allgather`` of
        ``[count, (tag, aprev) x SHARE_SLOTS]`` per rank (a slab has 1 or 2 such atoms); a
        second round with the real sizes only if a rank has more."""
        kernel, k = self._kernel, SHARE_SLOTS
        n = kernel.boundary_atoms(tag, nlocal, nall, self._tmap, self._edge)
        send = np.zeros(1 + 2 * k)
        send[0] = n
        if n <= k:
            kernel.pack_aprev(tag, aprev, self._edge, n, send[1:])
        blocks = np.empty((self.nprocs, 1 + 2 * k))
        self._mpi.Allgather(send, blocks)
        counts = blocks[:, 0].astype(np.int64)
        if counts.max() <= k:
            for block, c in zip(blocks, counts):
                kernel.unpack_aprev(tag, nlocal, nall, self._tmap, aprev, block[1:1 + 2 * c])
            return
        send = np.empty(2 * n)
        kernel.pack_aprev(tag, aprev, self._edge, n, send)
        recv = np.empty(int(2 * counts.sum()))
        self._mpi.Allgatherv(send, [recv, 2 * counts])
        kernel.unpack_aprev(tag, nlocal, nall, self._tmap, aprev, recv)

    def _account(self, step, tag, nev, power, ext_power=0.0):
        """This step's events (contact order), dissipation and (driven scenes) the
        excitations' work, each rate by the trapezoidal rule between step ends; with several
        ranks into this rank's partial sums until the next :meth:`_sync_hook` (as fix
        mdgran/chain does)."""
        ev = self._ev[:nev]
        left = tag[ev[:, 0].astype(np.int64)] if nev else ()
        for r in np.argsort(left, kind="stable") if nev else ():
            lt = int(left[r])
            kind = CLOSE if ev[r, 1] == 1.0 else OPEN
            if self._mpi is None:
                self.d_hyst += float(ev[r, 3])
                self.events.append(Event(float(ev[r, 2]), self._contact_number(lt), kind))
                self.stats["events"] += 1
            else:
                self._part[0] += float(ev[r, 3])
                self._events_part.append((int(step), lt, kind, float(ev[r, 2])))
        if self._last_step is not None:  # trapezoidal rule on the damping power
            dv = 0.5 * (power + self._power_prev) * self.dt
            if self._mpi is None:
                self.d_visc += dv
            else:
                self._part[1] += dv
            if self._flags.driven:
                dw = 0.5 * (ext_power + self._work_prev) * self.dt
                if self._mpi is None:
                    self.work += dw
                else:
                    self._part[2] += dw
        self._power_prev = power
        self._work_prev = ext_power
        self._last_step = step
        self.stats["steps"] = int(step)

    def _contact_number(self, left_tag):
        """Contract number of the contact whose left atom has tag ``left_tag`` (tag ``k`` is
        the ``k``-th atom along the line, walls included)."""
        return first_contact(self.walls) + left_tag - 1

    def _kernel_error(self, err, tag, value, step):
        kernel, t = self._kernel, step * self.dt
        if err == kernel.NON_FINITE:
            return IntegrationError(f"non-finite force at t = {t:.12g}, bead "
                                    f"{tag - 1 if self.walls else tag}")
        if err == kernel.BEYOND_TABLE:
            return IntegrationError(
                f"compression {value:.4g} beyond the contact table (delta_max = "
                f"{self.table.delta_max:g}) at t = {t:.12g}, contact {self._contact_number(tag)}")
        return IntegrationError(f"contact {self._contact_number(tag)} is closed but bead tag "
                                f"{tag + 1} is beyond the ghost cut-off at t = {t:.12g}")

    def _sync_hook(self):
        """After a run on several ranks (collective): the ranks' dissipation added in one sum,
        their events in (step, contact) order, and the first error of any rank on every rank."""
        comm = self._mpi
        total = np.empty(3)
        comm.Allreduce(self._part, total)
        self.d_hyst += float(total[0])
        self.d_visc += float(total[1])
        self.work += float(total[2])
        self._part[:] = 0.0
        err = None
        if self._error is not None:
            err = (isinstance(self._error, IntegrationError), str(self._error))
        gathered = comm.allgather((self._events_part, err))
        self._events_part = []
        found = sorted(e for part, _ in gathered for e in part)
        for step, lt, kind, te in found:
            self.events.append(Event(te, self._contact_number(lt), kind))
        self.stats["events"] += len(found)
        errors = [e for _, e in gathered if e is not None]
        if errors and self._error is None:
            plain, msg = errors[0]
            self._error = IntegrationError(msg) if plain else RuntimeError(msg)

    # ---- frames ------------------------------------------------------------------------
    def _gather(self):
        lmp = self.lmp
        x = np.ctypeslib.as_array(lmp.gather_atoms("x", 1, 3)).reshape(-1, 3)[:, 0]
        v = np.ctypeslib.as_array(lmp.gather_atoms("v", 1, 3)).reshape(-1, 3)[:, 0]
        disp = x - self.x0[1:]
        if self.walls:
            return disp[1:-1].copy(), v[1:-1].copy()
        return disp.copy(), v.copy()

    def _native_events(self, first, end):
        """Rows ``first .. end - 1`` of fix mdgran/chain's event table (its global array: time,
        contact, kind, step) as :class:`Events`, copied in one call (read one value at a time
        through LAMMPS's library interface, an event cost ~10 us), and released: the fix holds
        a frame's events, not the run's."""
        rows = np.empty((end - first, 4))
        got = self._read_events(self.lmp.lmp, b"contact", first, end - first,
                                rows.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), 1)
        if got != end - first:
            raise RuntimeError(f"fix mdgran/chain gave {got} of its events {first} .. {end - 1}")
        return Events(rows[:, 0], rows[:, 1].astype(np.int64), rows[:, 2].astype(np.int8))

    def _frame(self, k, t):
        if self.contact == "native":
            self._read_native()
        else:  # per-atom states by tag: the state of the contact to the atom's right
            state = np.ctypeslib.as_array(self.lmp.gather("i_closed", 0, 1))
            self.closed = state[:self.model.n_contacts] != 0
        x, v = self._gather()
        fr = Frame(step=k, time=float(t), x=x, v=v, closed=self.closed.copy(),
                   dissipated_viscous=self.d_visc, dissipated_hysteresis=self.d_hyst,
                   events=Events.of(self.events), external_work=self.work)
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
        if self.contact == "hook" and self._mpi is not None:
            self._sync_hook()  # every rank raises the first error of any rank
        if self._error is not None:
            if isinstance(self._error, IntegrationError):
                raise self._error
            raise IntegrationError(f"contact hook failed at t = "
                                   f"{(self._last_step or 0) * self.dt:.12g}: {self._error!r}")

    def _runs(self, resume):
        """Set up LAMMPS and run it to each output time; yields ``(k, t)`` after frame ``k``'s
        ``run`` (frame 0: the set-up), closes LAMMPS at the end."""
        if resume is not None:
            raise IntegrationError("the LAMMPS backend cannot resume from a checkpoint")
        wall0 = _time.perf_counter()
        self._start()
        lmp = self.lmp
        try:
            out_times = self.output_times()
            self._advance("run 0 post no")  # set-up: the callback sees the initial state
            yield 0, 0.0
            for k in range(1, len(out_times)):
                self._advance(f"run {self.steps_per_frame} pre no post no")
                yield k, float(out_times[k])
        finally:
            self.stats["wall_time_s"] = _time.perf_counter() - wall0
            lmp.close()

    def frames(self, resume=None):
        with contextlib.closing(self._runs(resume)) as runs:
            for k, t in runs:
                yield self._frame(k, t)

    def blocks(self, resume=None):
        """One frame a block.  With the native fix's located events on a chain of like beads
        whose excitation, if any, is a pulse, a frame gathers only the beads of the fix's moved
        hull and the contacts touching them (:meth:`_hull_frame`): a long chain's frame costs
        the beads that moved (:attr:`~mdgran.backends.base.Frames.moved`)."""
        if not self._hull_frames():
            yield from super().blocks(resume)
            return
        with contextlib.closing(self._runs(resume)) as runs:
            for k, t in runs:
                yield self._hull_frame(k, t)

    def _hull_frames(self) -> bool:
        m = self.model
        return (self.contact == "native" and self.event_mode == "located" and not m.mixed
                and (m.drive is None or m.drive.base is None))

    def _moved_hull(self) -> tuple[int, int]:
        """The 0-based beads ``lo .. hi - 1`` of fix mdgran/chain's moved hull (its vector's
        5th and 6th elements, tags; outside it every bead is at its initial place and at rest,
        and every contact between two such beads in its initial state)."""
        lo, hi = (int(self.lmp.extract_fix("contact", 0, 1, k)) for k in (4, 5))
        w = 1 if self.walls else 0
        lo, hi = max(lo - 1 - w, 0), min(hi - w, self.n)
        return (lo, hi) if lo < hi else (0, 0)

    def _gather_tags(self, name, first, atoms, values, fix=False):
        """``name`` (``values`` per atom) of the atoms with tags ``first .. first + atoms -
        1`` (``[atoms, values]``; a fix's per-atom vector with ``fix``): LAMMPS's subset
        gathers, O(atoms)."""
        ids = np.arange(first, first + atoms, dtype=np.int32)
        ptr = ids.ctypes.data_as(ctypes.POINTER(ctypes.c_int))
        gather = self.lmp.gather_subset if fix else self.lmp.gather_atoms_subset
        data = gather(name, 1, values, atoms, ptr)
        return np.ctypeslib.as_array(data).reshape(atoms, values)

    def _hull_frame(self, k, t) -> Frames:
        """Frame ``k`` as a block of one, from the beads of the moved hull alone: the others
        hold ``x = v = +0.0`` and their contacts the initial state."""
        from ...model.chain import initial_states, touching_contacts
        from ...rest_blocks import lazy_zeros

        self._read_native_sums()
        lo, hi = self._moved_hull()
        self.stats["front"] = [lo + 1, hi] if lo < hi else None  # 1-based beads
        m, w = self.model, 1 if self.walls else 0
        x, v = lazy_zeros((1, self.n)), lazy_zeros((1, self.n))
        closed = initial_states(self.n, self.walls, m.gap)[None]
        if hi > lo:
            first = lo + 1 + w  # tag of bead lo
            x[0, lo:hi] = self._gather_tags("x", first, hi - lo, 3)[:, 0] - \
                self.x0[first:first + hi - lo]
            v[0, lo:hi] = self._gather_tags("v", first, hi - lo, 3)[:, 0]
            c0, c1 = touching_contacts(self.n, self.walls, lo, hi)
            if c1 > c0:  # contact j: the state on atom (tag) j + 1
                closed[0, c0:c1] = self._gather_tags("f_contact", c0 + 1, c1 - c0, 1,
                                                     fix=True)[:, 0] != 0.0
        events, self.events = self.events, []
        return Frames(m, np.array([k]), np.array([t]), x, v, closed, np.array([self.d_visc]),
                      np.array([self.d_hyst]), np.array([self.work]), events,
                      np.array([len(events)]), moved=(lo, hi))
