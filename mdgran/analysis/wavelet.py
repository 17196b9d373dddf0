"""Morlet wavelet spectrum of a bead's motion (paper Fig. 3b-e), by FFT.

For a signal ``y(t)`` sampled at spacing ``dt`` and analysis frequencies ``omega_a`` (rad per
time unit), the transform is computed in the Fourier domain::

    W(omega_a, t) = 2 * IFFT[ Y(omega) H(omega) exp(-(omega0 omega / omega_a - omega0)^2 / 2) ]

with ``H`` the unit step (positive frequencies only: an analytic Morlet wavelet of centre
frequency ``omega0``, scale ``s = omega0 / omega_a``).  The Gaussian filter peaks at 1 exactly at
``omega = omega_a``, so a sinusoid ``A cos(omega t)`` gives ``|W| = A`` on the ridge
``omega_a = omega`` and the peak sits at the signal's frequency without correction.  The
relative bandwidth is ``1 / omega0`` (``omega0 = 6``: about 17 %); the time resolution at
``omega_a`` is about ``omega0 / omega_a``.  The mean is removed and the signal zero-padded to
twice its length (next power of 2) to limit wrap-around; values within about
``2 omega0 / omega_a`` of either end still feel the edges.
"""
from __future__ import annotations

import numpy as np

OMEGA0 = 6.0


def morlet_cwt(y, dt: float, omegas, omega0: float = OMEGA0) -> np.ndarray:
    """Complex Morlet transform ``W`` [len(omegas), len(y)] (units of ``y``)."""
    y = np.asarray(y, float) - np.mean(y)
    n = len(y)
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    Y = np.fft.fft(y, nfft)
    om = 2.0 * np.pi * np.fft.fftfreq(nfft, dt)
    pos = om > 0
    out = np.empty((len(omegas), n), complex)
    for k, oa in enumerate(np.asarray(omegas, float)):
        filt = np.zeros(nfft)
        filt[pos] = np.exp(-0.5 * (omega0 * om[pos] / oa - omega0) ** 2)
        out[k] = 2.0 * np.fft.ifft(Y * filt)[:n]
    return out


def default_omegas(dt: float, duration: float, count: int = 200, omega0: float = OMEGA0):
    """Log-spaced analysis frequencies from about two periods per record to half Nyquist."""
    lo = 2.0 * 2.0 * np.pi / duration
    hi = 0.5 * np.pi / dt
    return np.geomspace(lo, hi, count)


def wavelet_spectrum(traj, bead: int, omegas=None, quantity: str = "x", t0=None, t1=None,
                     omega0: float = OMEGA0):
    """``|W|`` of bead ``bead`` (1-based) of a run over frames in ``[t0, t1]``.

    ``quantity``: ``"x"`` (displacement) or ``"v"`` (velocity).  Returns
    ``(time [F'], omegas [K] rad per time unit, amplitude [K, F'])``.  The frames must be evenly
    spaced (they are: ``run.output_interval``).
    """
    t = traj.time
    sel = np.ones(len(t), bool)
    if t0 is not None:
        sel &= t >= t0
    if t1 is not None:
        sel &= t <= t1
    t = t[sel]
    y = getattr(traj, quantity)[sel, bead - 1]
    dt = float(t[1] - t[0])
    if omegas is None:
        omegas = default_omegas(dt, float(t[-1] - t[0]), omega0=omega0)
    return t, np.asarray(omegas, float), np.abs(morlet_cwt(y, dt, omegas, omega0))


def peak_frequency(omegas, amplitude) -> np.ndarray:
    """Ridge: frequency of the largest ``|W|`` at each time [F] (rad per time unit)."""
    return np.asarray(omegas)[np.argmax(amplitude, axis=0)]
