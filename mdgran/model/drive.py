"""Imposed excitations beyond the initial impulse: a force pulse on one bead and a motion of
the substrate's base (scene sections ``[pulse]`` and ``[base]``; docs/excitation.md).

Units are the reference bead's (force eta, time 1/q, length p).

**Force pulse** (half-sine) on bead ``b``, from ``t0`` for a duration ``T``::

    F(t) = A sin(pi (t - t0) / T)   for t0 <= t <= t0 + T, else 0

Its impulse is ``J = 2 A T / pi``: a short pulse is an ideal impulse of velocity ``J / m_b``.

**Base motion** ``u_b(t)``: the substrate springs and dampers act on ``x_i - u_b`` and
``v_i - u_b'``::

    F_sub,i = -g_i (k1 (x_i - u_b) + k3 (x_i - u_b)^3 + c_s (v_i - u_b'))

given by samples at a uniform interval ``h_b`` from ``t = 0``: of the displacement (a clamped
cubic spline through them: ``u_b' = 0`` at both ends; the first sample must be 0, the base
starts at rest at 0), or of the acceleration (linear between samples, integrated exactly from
rest at 0: ``u_b`` is then a cubic in each interval).  After the last sample the base moves on
at its last velocity (0 for a displacement series).  The walls, if any, stay at 0.

**Work.**  The energy ledger gains ``external_work`` ``W``, the work the excitations do::

    dW/dt = F(t) v_b + u_b'(t) sum_i F_sub,i

so that ``kinetic + contact + substrate + dissipated - W`` stays constant (the substrate
energy is that of the stretched springs, ``g_i (k1 (x_i - u_b)^2 / 2 + k3 (x_i - u_b)^4 /
4)``, and the substrate damping dissipates ``g_i c_s (v_i - u_b')^2``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Pulse:
    """Half-sine force ``amplitude`` (eta) on bead ``bead`` (0-based) from ``start`` for
    ``duration`` (1/q)."""

    bead: int
    amplitude: float
    duration: float
    start: float = 0.0

    def force(self, t: float) -> float:
        """F(t) (eta)."""
        s = (t - self.start) / self.duration
        if not 0.0 <= s <= 1.0:
            return 0.0
        return self.amplitude * math.sin(math.pi * s)

    @property
    def impulse(self) -> float:
        """``J = 2 A T / pi`` (units m p q)."""
        return 2.0 * self.amplitude * self.duration / math.pi


@dataclass(frozen=True)
class BaseMotion:
    """``u_b(t)`` as cubics on a uniform grid: ``coef[k] = (c3, c2, c1, c0)`` gives
    ``u_b = ((c3 s + c2) s + c1) s + c0`` at ``s = t - k h`` in interval ``k``; the last
    row is the motion after the samples (``c3 = c2 = 0``).  ``step`` = ``h`` (1/q)."""

    step: float
    coef: np.ndarray = field(repr=False)

    def _piece(self, t):
        t = np.asarray(t, dtype=float)
        k = np.minimum(np.floor(np.maximum(t, 0.0) / self.step), len(self.coef) - 1)
        return self.coef[k.astype(np.int64)], t - k * self.step

    def position(self, t):
        """u_b(t) (p)."""
        c, s = self._piece(t)
        return ((c[..., 0] * s + c[..., 1]) * s + c[..., 2]) * s + c[..., 3]

    def velocity(self, t):
        """u_b'(t) (p q)."""
        c, s = self._piece(t)
        return (3.0 * c[..., 0] * s + 2.0 * c[..., 1]) * s + c[..., 2]

    def at(self, t: float) -> tuple:
        """``(u_b, u_b')`` at one time t (float): the same cubic as :meth:`position` and
        :meth:`velocity`, one piece lookup in plain floats (the reference backend's right-hand
        side asks for it a few times per evaluation)."""
        k = min(math.floor(max(t, 0.0) / self.step), len(self.coef) - 1)
        c3, c2, c1, c0 = self.coef[k].tolist()
        s = t - k * self.step
        return ((c3 * s + c2) * s + c1) * s + c0, (3.0 * c3 * s + 2.0 * c2) * s + c1

    @property
    def peak_velocity(self) -> float:
        """max ``|u_b'|`` (p q), over the samples' grid and each cubic's extremum."""
        c = self.coef
        s = np.linspace(0.0, self.step, 9)
        v = (3.0 * c[:, :1] * s + 2.0 * c[:, 1:2]) * s + c[:, 2:3]
        return float(np.max(np.abs(v)))


    @property
    def end(self) -> float:
        """The time of the last sample (1/q): the motion's pieces end there."""
        return self.step * (len(self.coef) - 1)

    def peak_displacement(self, t_end: float) -> float:
        """max ``|u_b|`` (p) over ``[0, t_end]``: over each cubic on a grid and its ends, and the
        motion after the samples up to ``t_end``."""
        c = self.coef[:-1]
        s = np.linspace(0.0, self.step, 9)
        u = ((c[:, :1] * s + c[:, 1:2]) * s + c[:, 2:3]) * s + c[:, 3:4]
        last = max(abs(float(self.position(self.end))),
                   abs(float(self.position(max(t_end, self.end)))))
        return max(float(np.max(np.abs(u))) if len(c) else 0.0, last)


def base_from_displacement(step: float, u) -> BaseMotion:
    """The clamped cubic spline through displacement samples ``u`` (``u[0] = 0``) at
    ``t = k step``; held at ``u[-1]`` after them."""
    from scipy.interpolate import CubicSpline

    u = np.asarray(u, dtype=float)
    t = step * np.arange(len(u))
    spline = CubicSpline(t, u, bc_type="clamped")
    coef = np.zeros((len(u), 4))
    coef[:-1] = spline.c.T
    coef[-1, 3] = u[-1]
    return BaseMotion(float(step), coef)


def base_from_acceleration(step: float, a) -> BaseMotion:
    """Acceleration samples ``a`` at ``t = k step``, linear between them, integrated from
    rest at 0: in interval k, ``u_b = u_k + v_k s + a_k s^2 / 2 + (a_(k+1) - a_k) s^3 /
    (6 step)``; after the samples the base keeps its last velocity."""
    a = np.asarray(a, dtype=float)
    h = float(step)
    m = len(a) - 1
    coef = np.zeros((m + 1, 4))
    u = v = 0.0
    for k in range(m):
        jerk = (a[k + 1] - a[k]) / h
        coef[k] = (jerk / 6.0, 0.5 * a[k], v, u)
        u += ((jerk / 6.0 * h + 0.5 * a[k]) * h + v) * h
        v += (0.5 * jerk * h + a[k]) * h
    coef[m, 2:] = (v, u)
    return BaseMotion(h, coef)


@dataclass(frozen=True)
class Drive:
    """The scene's excitations: a :class:`Pulse`, a :class:`BaseMotion`, each or None."""

    pulse: Pulse | None = None
    base: BaseMotion | None = None

    def __bool__(self) -> bool:
        return self.pulse is not None or self.base is not None

    def energy(self, mass, substrate, k1: float, k3: float, t_end: float) -> float:
        """The excitations' energy scale (eta p), for the ledger's errors: the pulse's
        ``J^2 / (2 m_b)`` (the kinetic energy its impulse gives a free bead) plus, for the
        base, per bead the smaller of ``m max|u_b'|^2 / 2`` (the bead moving with the base at
        its fastest: a slow motion) and ``g (k1 U^2 / 2 + k3 U^4 / 4)``, ``U = max|u_b|`` up
        to ``t_end`` (the substrate stretched by the base's largest displacement: a motion
        faster than the substrate's period moves the beads by much less).  ``mass`` and
        ``substrate`` (g, 0 or 1) per bead."""
        e = 0.0
        if self.pulse is not None:
            e += self.pulse.impulse**2 / (2.0 * float(mass[self.pulse.bead]))
        if self.base is not None:
            mass = np.asarray(mass, dtype=float)
            u = self.base.peak_displacement(t_end)
            moving = 0.5 * mass * self.base.peak_velocity**2
            spring = np.asarray(substrate, dtype=float) * (0.5 * k1 * u * u + 0.25 * k3 * u**4)
            e += float(np.sum(np.minimum(moving, spring)))
        return e

    def base_at(self, t) -> tuple:
        """``(u_b, u_b')`` at t; ``(0, 0)`` without a base motion."""
        if self.base is None:
            return 0.0, 0.0
        return self.base.at(float(t))


def drive_from_scene(scene) -> Drive | None:
    """The scene's :class:`Drive`, or None when it has neither a pulse nor a base motion."""
    p, b = scene.pulse, scene.base
    pulse = base = None
    if p.amplitude:
        pulse = Pulse(int(p.bead) - 1, float(p.amplitude), float(p.duration), float(p.start))
    if b.kind == "displacement":
        base = base_from_displacement(b.interval, b.values)
    elif b.kind == "acceleration":
        base = base_from_acceleration(b.interval, b.values)
    drive = Drive(pulse, base)
    return drive if drive else None
