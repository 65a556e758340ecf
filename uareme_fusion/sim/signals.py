"""Scalar signals of time with analytic first and second derivatives, for smooth trajectories:
polynomial ramps, sums of sines and constants (`Signal`), used by `trajectory`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def ramp(t: np.ndarray, t0: float, duration: float, order: int) -> tuple[np.ndarray, ...]:
    """Raised-cosine step from 0 to 1 over [t0, t0 + duration], or (order=1) its time integral.

    Returns (value, first derivative, second derivative) in units of 1/s^k.
    """
    u = np.clip((t - t0) / duration, 0.0, 1.0)
    inside = (t > t0) & (t < t0 + duration)
    s = 0.5 * (1.0 - np.cos(np.pi * u))
    ds = np.where(inside, 0.5 * np.pi / duration * np.sin(np.pi * u), 0.0)
    dds = np.where(inside, 0.5 * (np.pi / duration) ** 2 * np.cos(np.pi * u), 0.0)
    if order == 0:
        return s, ds, dds
    # Integral of s from t0 to t: T (u/2 - sin(pi u) / (2 pi)) inside, t - t0 - T/2 after.
    integral = duration * (u / 2.0 - np.sin(np.pi * u) / (2.0 * np.pi))
    integral = np.where(t >= t0 + duration, t - t0 - duration / 2.0, integral)
    return integral, s, ds


@dataclass(frozen=True)
class Signal:
    """A smooth scalar function of time with analytic derivatives.

    value(t) = sum_k c_k t^k + sum_j A_j sin(w_j t + phi_j) + sum_r h_r ramp_r(t), where each ramp
    is a raised-cosine step (order 0) or its integral (order 1) starting at t0 and lasting T.
    Units are whatever the caller gives (rad for angles, m for positions, m/s for speeds).
    """

    poly: tuple[float, ...] = (0.0,)
    sines: tuple[tuple[float, float, float], ...] = ()
    """(amplitude, angular frequency rad/s, phase rad) triples."""
    ramps: tuple[tuple[float, float, float, int], ...] = ()
    """(height, t0 s, duration s, order) quadruples."""

    def __call__(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(value, d/dt, d^2/dt^2) at times `t_s` (any shape)."""
        t = np.asarray(t_s, dtype=float)
        p = np.polynomial.Polynomial(self.poly)
        v, d1, d2 = p(t), p.deriv(1)(t), p.deriv(2)(t)
        for amp, w, phi in self.sines:
            arg = w * t + phi
            v = v + amp * np.sin(arg)
            d1 = d1 + amp * w * np.cos(arg)
            d2 = d2 - amp * w * w * np.sin(arg)
        for height, t0, dur, order in self.ramps:
            r0, r1, r2 = ramp(t, t0, dur, order)
            v, d1, d2 = v + height * r0, d1 + height * r1, d2 + height * r2
        return v, d1, d2


def random_sines(rng: np.random.Generator, n: int, amp: float, f_lo_hz: float, f_hi_hz: float):
    """n sinusoids of total amplitude <= amp with random frequencies and phases."""
    amps = rng.uniform(0.5, 1.0, n)
    amps *= amp / amps.sum()
    freqs = 2 * np.pi * rng.uniform(f_lo_hz, f_hi_hz, n)
    phases = rng.uniform(0, 2 * np.pi, n)
    return tuple((float(a), float(w), float(p)) for a, w, p in zip(amps, freqs, phases))


def const_signal(value: float) -> Signal:
    return Signal(poly=(float(value),))
