"""Hot loop of the fast backend: velocity Verlet on plain numpy arrays, compiled with numba.

Units and equations are those of :mod:`mdgran.chain` (bead mass 1, nondimensional)::

    x_i'' = a_i = F_i - F_(i+1) - k1 x_i - k3 x_i^3,
    F_k   = closed_k * (f(delta_k) + c * d delta_k/dt),   delta_k = x_left - x_right - gap

**One step** of length ``h`` from ``(x0, v0, a0)`` (velocity Verlet; the damping force makes
``a`` depend on ``v``, so the end velocity is predicted first)::

    v_half = v0 + h/2 a0,   x1 = x0 + h v_half            (= x0 + h v0 + h^2/2 a0)
    v_est  = v_half + h/2 a0                               (= v(t+h) + O(h^2))
    a1     = a(x1, v_est)                                  (damping rate from v_est)
    v1     = v_half + h/2 a1
    D_visc += h/2 (P0 + P1),   P = c * sum_closed (d delta/dt)^2 from v_est

The prediction error ``O(h^2)`` in the damping force enters ``v1`` multiplied by ``h``, so the
method stays second order.  Everything for one step is one fused pass over the beads (each
bead is read and written once); two copies of ``(x, v, a)`` alternate as old and new buffers.

**Events** (``locate = True``).  Inside a step every bead moves on the parabola
``x0 + s v0 + s^2/2 a0``, so each contact's event function ``g`` (``delta - delta_off`` when
closed, ``-delta`` when open; positive inside the state) is exactly the quadratic
``g(s) = g0 + s g0' + s^2/2 g0''`` along the step.  The pass flags a contact when its end value
could hide a crossing (``g1 < 0`` or ``g1 < h/2 g'(h)``: a dip below zero inside the step
implies this, so the filter never misses one).  For flagged contacts the first downward root
of the quadratic is solved in closed form; the step is redone to the earliest root ``te``,
where the contact switches (``D_hysteresis += V(delta(te))`` on opening, exact law, as the
reference does), the accelerations of its two beads and the damping power are updated, and
the rest of the step ``h - te`` is integrated in the new state (repeated for further events).
A contact that sits on its switching point after a switch (DMT, Hertz: ``delta_off = 0``) is
switched back at once if it moves outward (the reference's settle rule); more than
``MAX_SWITCHES`` switches of one contact at one instant stop the run (chatter).

``locate = False``: plain step-quantized Verlet, as a fixed-step MD code: after each step a
closed contact with ``delta <= delta_off`` opens and an open one with ``delta >= 0`` closes
(strict inequalities when ``delta_off = 0``), before the force at the new positions is
computed; the event time is interpolated linearly in the step (as the LAMMPS backend does).

**Force** ``f(delta)``: the table of :class:`mdgran.contact.ContactTable`, nodes uniform in
``w = sqrt(delta - base)`` (``base = delta_min``, 0 for Hertz) with a cubic spline in ``w``
between them (``tab[i]`` = the cubic's coefficients on interval ``i``), or the exact law
(``exact = True``: Newton inversion, slower).  Hertz always uses the exact ``delta^(3/2)``
(cheaper than the table, and free of the spline's round-off force near ``delta = 0``, which
made resting contacts ahead of the pulse flicker).  Energies at events use the exact law.

Terms switched off (walls, damping, k1, k3, event location, exact law) are compile-time
constants of :func:`get_kernel`: each combination is a separately compiled variant (cached
on disk by numba), so an absent term costs nothing in the loop.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

# status codes (st[ST_STATUS])
OK, OUT_OF_TABLE, CHATTER, TOO_MANY_SUBSTEPS, EVENTS_FULL, EVENT_OVERFLOW = 0, 1, 2, 3, 4, 5
# integer state st[...]
ST_CUR, ST_STEP, ST_EVN, ST_STATUS, ST_BAD, ST_NFLAG, ST_CHATN, ST_SUBSTEPS = range(8)
N_ST = 8
# float state sc[...]
SC_DVISC, SC_DHYST, SC_POWER, SC_BADT, SC_CHATT = range(5)
N_SC = 5
# parameters pr[...]
(PR_GAP, PR_C, PR_K1, PR_K3, PR_DOFF, PR_BASE, PR_TSCALE, PR_WLIM, PR_DMAX, PR_FC, PR_SIGMA,
 PR_TMIN, PR_DMIN, PR_E0, PR_SING, PR_WSTEP) = range(16)
N_PR = 16

MAX_SWITCHES = 4  # switches of one contact at one instant before the run stops (chatter)
MAX_SUBSTEPS = 10000  # event splits in one step
SIMULTANEOUS = 1e-12  # events within SIMULTANEOUS * (1 + t) of the earliest switch with it
#: The state invariant (as the reference's): no contact beyond its switching point by more
#: than this (units of p) after a step; one found beyond it switches at once.
STATE_TOL = 1e-12
FLAG_CAP = 64  # flagged contacts remembered per pass (beyond: all contacts are scanned)
CHAT_CAP = 64
#: Closed contacts with delta below delta_min + SING_BAND get the mean-force kick (Schwarz,
#: displacement rule); see `law_mean_force`.
SING_BAND = 0.1
# 5-point Gauss-Legendre nodes and weights on [-1, 1]
GL_X = np.array([-0.9061798459386640, -0.5384693101056831, 0.0, 0.5384693101056831,
                 0.9061798459386640])
GL_W = np.array([0.2369268850561891, 0.4786286704993665, 0.5688888888888889,
                 0.4786286704993665, 0.2369268850561891])


# ---- the exact law (events, energies, and the optional exact force) ----------------------
@njit(cache=True)
def branch_t(d, sigma, tm, dmin):
    """Branch parameter t >= t_min with t^4 - 4 sigma t = d (Newton on sqrt(d - dmin), as
    :meth:`mdgran.contact.ContactLaw.t_of_delta`); clamped to t_min below dmin."""
    rhs = math.sqrt(max(d - dmin, 0.0))
    if tm == 0.0:
        return math.sqrt(rhs)
    big = 6.0 * tm * tm
    w = min(rhs / math.sqrt(big), math.sqrt(rhs))
    for _ in range(7):
        sq = math.sqrt(w * w + 4.0 * tm * w + big)
        w = w - (w * sq - rhs) / (sq + w * (w + 2.0 * tm) / sq)
    return tm + max(w, 0.0)


@njit(cache=True)
def law_force(d, hertz, pr):
    """Exact attached-branch force f(delta) (units eta)."""
    if hertz:
        dp = max(d, 0.0)
        return dp * math.sqrt(dp)
    t = branch_t(d, pr[PR_SIGMA], pr[PR_TMIN], pr[PR_DMIN])
    u = t * t * t - 3.0 * pr[PR_SIGMA]
    return pr[PR_FC] + u * u


@njit(cache=True)
def law_energy(d, hertz, pr):
    """Exact contact energy V(delta) = integral_0^delta f (units eta p)."""
    if hertz:
        dp = max(d, 0.0)
        return 0.4 * dp * dp * math.sqrt(dp)
    sg, fc = pr[PR_SIGMA], pr[PR_FC]
    t = branch_t(d, sg, pr[PR_TMIN], pr[PR_DMIN])
    t3 = t * t * t
    p = (0.4 * t3 * t3 * t3 * t - 4.0 * sg * t3 * t3 * t + (fc + 15.0 * sg * sg) * t3 * t
         - 4.0 * sg * (fc + 9.0 * sg * sg) * t)
    return p - pr[PR_E0]


# ---- helpers: ``cfg = (walls, damped, k1_on, k3_on, locate, exact, hertz)`` --------------
# The hot ones are inlined (numba IR) into each compiled variant, where ``cfg`` is a constant,
# so the branches on it fold away; the rare-path ones take ``cfg`` at run time.
@njit(inline="always")
def beads(walls, j):
    """Left and right bead of contact j (walls: j-1, j, the walls being -1 and n)."""
    if walls:
        return j - 1, j
    return j, j + 1


@njit(cache=True)
def diff(walls, x, j):
    """x_left - x_right of contact j (walls at x = 0)."""
    n = x.shape[0]
    left, right = beads(walls, j)
    xl = x[left] if left >= 0 else 0.0
    xr = x[right] if right < n else 0.0
    return xl - xr


@njit(inline="always")
def spline(tab, w, wstep):
    """Table force at table coordinate w = sqrt(delta - base) / wstep (0 <= w < n - 1): the
    cubic of interval i = floor(w), coefficients tab[i] (highest power first) in w_i offset."""
    i = int(w)
    x = (w - i) * wstep
    return ((tab[i, 0] * x + tab[i, 1]) * x + tab[i, 2]) * x + tab[i, 3]


@njit(inline="always")
def lawf(exact, hertz, d, pr, tab):
    """(f, ok): force f(delta) of a closed contact (table or exact law); ok is False beyond
    the table or for a non-finite delta."""
    if exact or hertz:  # Hertz: delta^(3/2) is cheaper than the table, and exact at 0
        if not (d < pr[PR_DMAX]):
            return 0.0, False
        return law_force(d, hertz, pr), True
    u = d - pr[PR_BASE]
    if u < 0.0:
        u = 0.0
    w = math.sqrt(u) * pr[PR_TSCALE]
    if not (w < pr[PR_WLIM]):
        return 0.0, False
    return spline(tab, w, pr[PR_WSTEP]), True


@njit(cache=True)
def record(j, t, kind, st, evt, evj, evk):
    """Append event (t, contact index j, kind 1 close / 0 open) to the buffers."""
    k = st[ST_EVN]
    if k >= evt.shape[0]:
        st[ST_STATUS] = EVENT_OVERFLOW
        st[ST_BAD] = j
        return
    evt[k] = t
    evj[k] = j
    evk[k] = kind
    st[ST_EVN] = k + 1


@njit(cache=True)
def quantized_switch(cfg, j, d, xo, h, t0, closed, pr, st, sc, evt, evj, evk):
    """locate = False: switch contact j, whose end-of-step compression d is past its
    switching point; the event time is interpolated linearly between the step's ends."""
    walls, hertz = cfg[0], cfg[6]
    thr = pr[PR_DOFF] if closed[j] else 0.0
    d0 = diff(walls, xo, j) - pr[PR_GAP]
    span = d0 - d
    frac = min(max((d0 - thr) / span if span != 0.0 else 1.0, 0.0), 1.0)
    if closed[j]:
        sc[SC_DHYST] += law_energy(d, hertz, pr)
        closed[j] = False
        record(j, t0 + frac * h, 0, st, evt, evj, evk)
    else:
        closed[j] = True
        record(j, t0 + frac * h, 1, st, evt, evj, evk)


@njit(inline="always")
def verlet_pass(cfg, xo, vo, ao, xn, vn, an, closed, h, t0, pr, tab, flags, st, sc, evt, evj, evk):
    """One Verlet step of length h from (xo, vo, ao) into (xn, vn, an); returns the damping
    power at the end (rates from v_est).

    One pass over the contacts from left to right: predict the right bead of the contact,
    compute the contact force, finish the left bead (its acceleration and end velocity).
    Closed contacts flag a possible event (locate) or switch at once (quantized).

    Near snap-off (displacement rule) the force goes as sqrt(delta - delta_min), and the
    trapezoid kick h/2 (f0 + f1) of Verlet errs by O(h^1.5) in the last steps before the
    event; for those contacts the kick uses the mean force (V(delta1) - V(delta0)) /
    (delta1 - delta0), exact along a straight path, through Fv = 2 f_mean - f0 (so that
    h/2 (f0 + Fv) = h f_mean): second order again.
    """
    walls, damped, k1_on, k3_on, locate, exact, hertz = cfg
    n = xo.shape[0]
    m = closed.shape[0]
    hh = 0.5 * h
    gap, c, k1, k3 = pr[PR_GAP], pr[PR_C], pr[PR_K1], pr[PR_K3]
    doff, base, tscale, wlim = pr[PR_DOFF], pr[PR_BASE], pr[PR_TSCALE], pr[PR_WLIM]
    dmax, sing, wstep = pr[PR_DMAX], pr[PR_SING], pr[PR_WSTEP]
    strict = doff == 0.0  # quantized DMT, Hertz: a contact resting at delta = 0 stays
    nflag = 0
    power = 0.0
    # left bead of the current contact: (x, v_half, v_est); the wall for walls
    x_c, vh_c, ve_c = 0.0, 0.0, 0.0
    if not walls:
        vh_c = vo[0] + hh * ao[0]
        x_c = xo[0] + h * vh_c
        ve_c = vh_c + hh * ao[0]
    f_l, fv_l = 0.0, 0.0  # force of the contact left of that bead (Fv: for the kick)
    rshift = 0 if walls else 1  # right bead of contact j
    for j in range(m):
        rb = j + rshift
        x_r, vh_r, ve_r = 0.0, 0.0, 0.0
        if rb < n:
            a_r = ao[rb]
            vh_r = vo[rb] + hh * a_r
            x_r = xo[rb] + h * vh_r
            ve_r = vh_r + hh * a_r
        d = x_c - x_r - gap
        r = ve_c - ve_r
        if not locate:
            if closed[j]:
                go = d < doff if strict else d <= doff
            else:
                go = d > 0.0 if strict else d >= 0.0
            if go:
                quantized_switch(cfg, j, d, xo, h, t0, closed, pr, st, sc, evt, evj, evk)
        f_r, fv_r = 0.0, 0.0
        if closed[j]:
            if hertz:  # exact: cheaper than the table, and no round-off force at delta = 0
                if not (d < dmax):
                    st[ST_STATUS] = OUT_OF_TABLE
                    st[ST_BAD] = j
                dp = d if d > 0.0 else 0.0
                f_r = dp * math.sqrt(dp)
            elif exact:
                if not (d < dmax):
                    st[ST_STATUS] = OUT_OF_TABLE
                    st[ST_BAD] = j
                f_r = law_force(d, hertz, pr)
            else:
                u = d - base
                if u < 0.0:
                    u = 0.0
                w = math.sqrt(u) * tscale
                if not (w < wlim):
                    st[ST_STATUS] = OUT_OF_TABLE
                    st[ST_BAD] = j
                    w = 0.0
                f_r = spline(tab, w, wstep)
            fv_r = f_r
            if d < sing:  # near snap-off: mean-force kick
                d0 = diff(walls, xo, j) - gap
                fv_r = 2.0 * law_mean_force(d0, d, pr) - law_force_at(exact, hertz, d0, pr, tab)
            if damped:
                f_r += c * r
                fv_r += c * r
                power += c * r * r
            g = d - doff
            gd = r
        else:
            g = -d
            gd = -r
        if locate:
            # a dip of g below 0 inside the step implies g1 < h/2 g'(h) (g is a parabola)
            if g < 0.0 or g < 0.5 * h * gd:
                if nflag < flags.shape[0]:
                    flags[nflag] = j
                nflag += 1
        if rb >= 1:  # finish the left bead
            a, av = bead_accelerations(f_l - f_r, fv_l - fv_r, x_c, k1_on, k1, k3_on, k3)
            xn[rb - 1] = x_c
            an[rb - 1] = a
            vn[rb - 1] = vh_c + hh * av
        x_c, vh_c, ve_c = x_r, vh_r, ve_r
        f_l, fv_l = f_r, fv_r
    if not walls:  # the last bead has no contact on its right
        a, av = bead_accelerations(f_l, fv_l, x_c, k1_on, k1, k3_on, k3)
        xn[n - 1] = x_c
        an[n - 1] = a
        vn[n - 1] = vh_c + hh * av
    st[ST_NFLAG] = nflag
    return power


@njit(cache=True, inline="always")
def bead_accelerations(f, fv, x, k1_on, k1, k3_on, k3):
    """A bead's acceleration from its net contact force ``f`` (and ``fv``, the same with the
    mean-force kick near snap-off) plus the substrate terms the scene switches on."""
    if k1_on:
        f -= k1 * x
        fv -= k1 * x
    if k3_on:
        f -= k3 * x * x * x
        fv -= k3 * x * x * x
    return f, fv


@njit(cache=True)
def law_force_at(exact, hertz, d, pr, tab):
    """f(delta) of a closed contact as the loop evaluates it (table or exact)."""
    f, ok = lawf(exact, hertz, d, pr, tab)
    return f


# ---- event location and switching (rare path; cfg at run time) --------------------------
@njit(cache=True)
def gfun(walls, j, x, v, a, closed, pr):
    """(g, g', g'') of contact j in its current state (g > 0 inside the state)."""
    d = diff(walls, x, j) - pr[PR_GAP]
    r = diff(walls, v, j)
    q = diff(walls, a, j)
    if closed[j]:
        return d - pr[PR_DOFF], r, q
    return -d, -r, -q


@njit(cache=True)
def first_root(walls, j, xo, vo, ao, xn, closed, h, pr):
    """First s in [0, h] where g(s) = g0 + s g0' + s^2/2 g0'' falls to min(g0, 0), or -1."""
    g0, b, q = gfun(walls, j, xo, vo, ao, closed, pr)
    c = 0.5 * q
    d1 = diff(walls, xn, j) - pr[PR_GAP]
    g1 = d1 - pr[PR_DOFF] if closed[j] else -d1
    if g0 <= 0.0:  # on its switching point (left alone: moving inward): event if it goes out
        if b < 0.0 or g0 < -STATE_TOL:  # moving out, or beyond it (the state invariant)
            return 0.0
        if c < 0.0 and -b / c <= h:
            return -b / c
        return h if g1 < g0 else -1.0
    s = -1.0
    if c == 0.0:
        if b < 0.0:
            s = -g0 / b
    else:
        disc = b * b - 4.0 * c * g0
        if disc >= 0.0:
            qq = -0.5 * (b + math.copysign(math.sqrt(disc), b))
            r1 = qq / c
            r2 = g0 / qq if qq != 0.0 else -1.0
            if r1 > 0.0 and (r2 <= 0.0 or r1 < r2):
                s = r1
            elif r2 > 0.0:
                s = r2
    if 0.0 <= s <= h:
        return s
    if g1 < 0.0:  # the pass saw it out at the end: rounding put the root past h
        return h
    return -1.0


@njit(cache=True)
def locate_events(walls, xo, vo, ao, xn, closed, h, tol, pr, flags, swl, st):
    """Earliest root te among the flagged contacts, and the contacts switching with it (into
    swl): returns (te, count), te = -1 if none."""
    nf = st[ST_NFLAG]
    scan_all = nf > flags.shape[0]
    cnt = closed.shape[0] if scan_all else nf
    te = -1.0
    for k in range(cnt):
        j = k if scan_all else flags[k]
        s = first_root(walls, j, xo, vo, ao, xn, closed, h, pr)
        if s >= 0.0 and (te < 0.0 or s < te):
            te = s
    if te < 0.0:
        return te, 0
    ns = 0
    for k in range(cnt):
        j = k if scan_all else flags[k]
        s = first_root(walls, j, xo, vo, ao, xn, closed, h, pr)
        if s >= 0.0 and s <= te + tol:
            if ns >= swl.shape[0]:
                st[ST_STATUS] = EVENT_OVERFLOW
                st[ST_BAD] = j
                return te, ns
            swl[ns] = j
            ns += 1
    return te, ns


@njit(cache=True)
def switch(cfg, j, t, x, v, a, closed, pr, tab, st, sc, evt, evj, evk, chat):
    """Switch contact j at time t in state (x, v, a): hysteresis loss V(delta) on opening,
    the event, the change of force on its two beads and of the damping power; chatter guard."""
    walls, damped, exact, hertz = cfg[0], cfg[1], cfg[5], cfg[6]
    n = x.shape[0]
    d = diff(walls, x, j) - pr[PR_GAP]
    r = diff(walls, v, j)
    f_old = 0.0
    f_new = 0.0
    if closed[j]:
        f_old, ok = lawf(exact, hertz, d, pr, tab)
        if damped:
            f_old += pr[PR_C] * r
            sc[SC_POWER] -= pr[PR_C] * r * r
        sc[SC_DHYST] += law_energy(d, hertz, pr)
        closed[j] = False
        record(j, t, 0, st, evt, evj, evk)
    else:
        closed[j] = True
        record(j, t, 1, st, evt, evj, evk)
        f_new, ok = lawf(exact, hertz, d, pr, tab)
        if not ok:
            st[ST_STATUS] = OUT_OF_TABLE
            st[ST_BAD] = j
        if damped:
            f_new += pr[PR_C] * r
            sc[SC_POWER] += pr[PR_C] * r * r
    left, right = beads(walls, j)
    df = f_new - f_old
    if left >= 0:
        a[left] -= df
    if right < n:
        a[right] += df
    # chatter guard: count the switches of each contact at this instant
    if abs(t - sc[SC_CHATT]) > SIMULTANEOUS * (1.0 + abs(t)):
        sc[SC_CHATT] = t
        st[ST_CHATN] = 0
    nc = st[ST_CHATN]
    for k in range(nc):
        if chat[k, 0] == j:
            chat[k, 1] += 1
            if chat[k, 1] > MAX_SWITCHES:
                st[ST_STATUS] = CHATTER
                st[ST_BAD] = j
            return
    if nc < chat.shape[0]:
        chat[nc, 0] = j
        chat[nc, 1] = 1
        st[ST_CHATN] = nc + 1


@njit(cache=True)
def settle(cfg, js, nj, t, x, v, a, closed, pr, tab, st, sc, evt, evj, evk, chat):
    """Switch at once every contact of js[:nj] on or over its switching point and moving
    outward (g <= 0, g' < 0), or beyond it by more than STATE_TOL, until none is (the
    reference's rule)."""
    while True:
        moved = False
        for k in range(nj):
            j = js[k]
            g, gd, _ = gfun(cfg[0], j, x, v, a, closed, pr)
            if g < -STATE_TOL or (g <= 0.0 and gd < 0.0):
                switch(cfg, j, t, x, v, a, closed, pr, tab, st, sc, evt, evj, evk, chat)
                moved = True
                if st[ST_STATUS] != OK:
                    return
        if not moved:
            return


@njit(cache=True)
def settle_all(cfg, t, x, v, a, closed, pr, tab, st, sc, evt, evj, evk, chat):
    """The initial settle, over every contact."""
    m = closed.shape[0]
    settle(cfg, np.arange(m), m, t, x, v, a, closed, pr, tab, st, sc, evt, evj, evk, chat)


@njit(cache=True)
def init_acc(cfg, x, v, a, closed, pr, tab, st):
    """a = a(x, v) for the current contact states; returns the damping power."""
    walls, damped, k1_on, k3_on, exact, hertz = cfg[0], cfg[1], cfg[2], cfg[3], cfg[5], cfg[6]
    n = x.shape[0]
    power = 0.0
    for i in range(n):
        a[i] = 0.0
        if k1_on:
            a[i] -= pr[PR_K1] * x[i]
        if k3_on:
            a[i] -= pr[PR_K3] * x[i] * x[i] * x[i]
    for j in range(closed.shape[0]):
        if not closed[j]:
            continue
        f, ok = lawf(exact, hertz, diff(walls, x, j) - pr[PR_GAP], pr, tab)
        if not ok:
            st[ST_STATUS] = OUT_OF_TABLE
            st[ST_BAD] = j
        if damped:
            r = diff(walls, v, j)
            f += pr[PR_C] * r
            power += pr[PR_C] * r * r
        left, right = beads(walls, j)
        if left >= 0:
            a[left] -= f
        if right < n:
            a[right] += f
    return power


# ---- the stepping loop, one compiled variant per cfg ---------------------------------------
@njit(inline="always")
def _advance(cfg, nsteps, dt, X, V, A, closed, pr, tab, flags, swl, st, sc, evt, evj, evk,
             chat):
    locate = cfg[4]
    for _ in range(nsteps):
        if st[ST_EVN] > evt.shape[0] // 2:
            st[ST_STATUS] = EVENTS_FULL
            return
        t0 = st[ST_STEP] * dt
        tol = SIMULTANEOUS * (1.0 + abs(t0))
        done = 0.0  # part of the step integrated so far
        h = dt
        redo = 0  # > 0: this pass is the step up to `redo` simultaneous events
        nsub = 0
        while True:
            o = st[ST_CUR]
            w = 1 - o
            st[ST_NFLAG] = 0
            p1 = verlet_pass(cfg, X[o], V[o], A[o], X[w], V[w], A[w], closed, h, t0 + done, pr, tab,
                       flags, st, sc, evt, evj, evk)
            if st[ST_STATUS] != OK:
                sc[SC_BADT] = t0 + done + h
                return
            ns = 0
            te = -1.0
            last = False  # the pass reaches the end of the step
            if redo > 0:  # this pass ends on the events
                ns, te = redo, h
            else:
                if locate and st[ST_NFLAG] > 0:
                    te, ns = locate_events(cfg[0], X[o], V[o], A[o], X[w], closed, h, tol, pr,
                                           flags, swl, st)
                    if st[ST_STATUS] != OK:
                        sc[SC_BADT] = t0 + done
                        return
                last = ns == 0 or te >= h - tol
            if last or redo > 0:  # keep this pass
                sc[SC_DVISC] += 0.5 * h * (sc[SC_POWER] + p1)
                sc[SC_POWER] = p1
                st[ST_CUR] = w
            if ns == 0:
                break
            if redo == 0 and not last and te > 0.0:
                redo, h = ns, te  # step again, up to the event
                continue
            tev = t0 + dt if last else t0 + done + te
            c = st[ST_CUR]
            for k in range(ns):
                switch(cfg, swl[k], tev, X[c], V[c], A[c], closed, pr, tab, st, sc, evt, evj,
                       evk, chat)
            settle(cfg, swl, ns, tev, X[c], V[c], A[c], closed, pr, tab, st, sc, evt, evj,
                   evk, chat)
            st[ST_SUBSTEPS] += 1
            nsub += 1
            if nsub > MAX_SUBSTEPS:
                st[ST_STATUS] = TOO_MANY_SUBSTEPS
                st[ST_BAD] = swl[0]
            if st[ST_STATUS] != OK:
                sc[SC_BADT] = tev
                return
            if last:
                break
            done += te
            h = dt - done
            redo = 0
        st[ST_STEP] += 1


@njit(cache=True)
def law_mean_force(d0, d1, pr):
    """Mean force over the compression interval, (V(d1) - V(d0)) / (d1 - d0) (Schwarz).

    In the branch parameter t it is the mean of f(t) weighted by delta'(t) = 4 (t^3 - sigma)
    >= 0 over [t0, t1]; f delta' is a polynomial of degree 9, so 5-point Gauss-Legendre is
    exact, and there is no cancellation when d1 - d0 is small.
    """
    sg, tm, fc = pr[PR_SIGMA], pr[PR_TMIN], pr[PR_FC]
    t0 = branch_t(d0, sg, tm, pr[PR_DMIN])
    t1 = branch_t(d1, sg, tm, pr[PR_DMIN])
    mid, half = 0.5 * (t0 + t1), 0.5 * (t1 - t0)
    num = 0.0
    den = 0.0
    for k in range(5):
        tau = mid + half * GL_X[k]
        t3 = tau * tau * tau
        wk = GL_W[k] * (t3 - sg)
        u = t3 - 3.0 * sg
        num += wk * (fc + u * u)
        den += wk
    if den <= 0.0:
        u = t0 * t0 * t0 - 3.0 * sg
        return fc + u * u
    return num / den


_KERNELS: dict = {}


def get_kernel(walls: bool, damped: bool, k1_on: bool, k3_on: bool, locate: bool,
               exact: bool, hertz: bool):
    """``(cfg, advance)``: the configuration tuple and the compiled stepping loop
    ``advance(nsteps, dt, X, V, A, closed, pr, tab, flags, swl, st, sc, evt, evj, evk, chat)``
    for one variant (compiled on first use, then cached on disk by numba)."""
    cfg = (bool(walls), bool(damped), bool(k1_on), bool(k3_on), bool(locate), bool(exact),
           bool(hertz))
    if cfg not in _KERNELS:
        _KERNELS[cfg] = (cfg, _make_advance(cfg))
    return _KERNELS[cfg]


def _make_advance(cfg):
    @njit(cache=True)
    def advance(nsteps, dt, X, V, A, closed, pr, tab, flags, swl, st, sc, evt, evj, evk, chat):
        """Advance up to nsteps steps of dt from the state in (X, V, A)[st[ST_CUR]]; stops
        early on an error or when the event buffer is half full (st[ST_STATUS])."""
        _advance(cfg, nsteps, dt, X, V, A, closed, pr, tab, flags, swl, st, sc, evt, evj,
                 evk, chat)

    return advance
