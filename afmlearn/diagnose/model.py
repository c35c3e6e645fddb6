"""`DiagnosisModel`: a fitted candidate (spec + linear coefficients) that can be simulated."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, final

import numpy as np
from numpy.typing import NDArray

from simulator import Scales

from ._kernel import simulate_model
from .balance import N_LEVER, PeriodicOrbit, harmonics, synthesize
from .spec import ModelSpec

__all__ = ["DiagnosisModel"]

FloatArray = NDArray[np.float64]


@final
@dataclass(frozen=True, eq=False)
class DiagnosisModel:
    """A fitted model (dimensionless; see :mod:`afmlearn.diagnose.spec`).

    Parameters
    ----------
    spec : ModelSpec
    coef : ndarray, shape (3 + n_force,)
        ``[K, D, B, c_1 .. c_m]``: stiffness, damping, drive amplitude [k L_ref], force
        coefficients (terms of ``spec.term_names()``).
    omega, gap : float
        Drive frequency / f0 and rest gap / L_ref.
    scales : simulator.Scales
    """

    spec: ModelSpec
    coef: FloatArray
    omega: float
    gap: float
    scales: Scales

    @property
    def force_coefficients(self) -> FloatArray:
        return np.asarray(self.coef[N_LEVER:], float)

    def force(self, z: FloatArray, zdot: FloatArray,
              attached: NDArray[np.bool_] | None = None) -> FloatArray:
        """``F_ts`` [k L_ref] along a trajectory (shape (n,)); ``attached`` for the neck."""
        if attached is None:
            attached = np.zeros(np.shape(z), bool)
        return self.spec.columns(np.asarray(z, float), np.asarray(zdot, float),
                                 attached) @ self.force_coefficients

    def orbit_force(self, x: FloatArray, v: FloatArray) -> FloatArray:
        """``F_ts`` along one period of a periodic true-deflection orbit (grid)."""
        z = self.gap - x
        return self.force(z, -v, self.spec.state(z))

    def inverted_force(self, orbit: PeriodicOrbit) -> FloatArray:
        """The force the measured orbit implies under this model's lever (grid, one period).

        ``F_n = B e^{-i phi} [n = 1] - (K - n^2 Omega^2 + i n Omega D) X_n / G_n``: the
        transfer-function inversion of the measured (denoised) orbit with the model's lever,
        second mode and detector -- what the tip felt if the lever model is right --
        smoothed with Lanczos sigma factors against the truncation's ringing.
        """
        _, _, X = orbit.true_orbit(self.spec)
        n = np.arange(X.size)
        K, D, B = (float(v) for v in self.coef[:N_LEVER])
        G = np.ones(n.size, complex)
        mode = self.spec.extra_mode
        if mode is not None:
            h2 = mode.response(n, self.omega)
            lever0 = 1.0 - (n * self.omega) ** 2 + 1j * n * self.omega / orbit.quality_factor
            G = 1.0 + mode.mode_parameters()[2] * lever0 * h2
        F = -(K - (n * self.omega) ** 2 + 1j * n * self.omega * D) * X / G
        F[1] += B * np.exp(-1j * self.spec.drive_phase)
        # Lanczos sigma factors: the inversion weighs harmonic n by ~n^2, so the truncated
        # series rings (Gibbs); the factors trade that for a little smoothing of the contact
        return synthesize(F * np.sinc(n / (n[-1] + 1)), orbit.grid)

    def measured(self, x: FloatArray) -> FloatArray:
        """What the detector reports for true deflection ``x``."""
        out = self.spec.output_map
        return x if out is None else out.measure(x)

    def mode2_orbit(self, orbit: PeriodicOrbit) -> tuple[FloatArray, FloatArray]:
        """Second-mode deflection and rate on the orbit grid (zeros for one mode)."""
        mode = self.spec.extra_mode
        if mode is None:
            return np.zeros(orbit.grid), np.zeros(orbit.grid)
        x, v, _ = orbit.true_orbit(self.spec)
        Fn = harmonics(self.orbit_force(x, v), orbit.n_h)
        n = np.arange(orbit.n_h + 1)
        h2 = mode.response(n, self.omega)
        d = np.zeros(n.size, complex)
        d[1] = self.coef[2] * np.exp(-1j * self.spec.drive_phase)
        Q2 = mode.mode_parameters()[2] * h2 * (d - Fn)
        return synthesize(Q2, orbit.grid), synthesize(Q2, orbit.grid, 1, self.omega)

    def kernel_args(self) -> tuple:
        """The model's arguments of :func:`._kernel.simulate_model` after ``n_samples,
        substeps``: lever vector, term encoding (library terms, then the neck's terms times its
        coefficient), ``a0``, ``d_c`` (0 without a neck or with its coefficient 0)."""
        s = self.spec
        kinds, p1, p2 = s.library().encode()
        n_lib = kinds.size
        c = self.force_coefficients
        mode = s.extra_mode
        k2, d2, g2 = mode.modal() if mode is not None else (0.0, 0.0, 0.0)
        lever = np.array([self.gap, self.coef[0], self.coef[1], self.coef[2], s.drive_phase,
                          self.omega, k2, d2, g2, float(mode is not None)])
        coefs = np.asarray(c[:n_lib], float)
        dc = 0.0
        if s.neck is not None and c[n_lib] != 0.0:
            nk, n1, n2, w = s.neck.encode(s.a0)
            kinds = np.concatenate([kinds, nk])
            p1 = np.concatenate([p1, n1])
            p2 = np.concatenate([p2, n2])
            coefs = np.concatenate([coefs, float(c[n_lib]) * w])
            dc = s.neck.neck_length()
        return (lever, np.ascontiguousarray(kinds, np.int64), np.ascontiguousarray(p1, float),
                np.ascontiguousarray(p2, float), np.ascontiguousarray(coefs), float(s.a0),
                float(dc))

    def simulate(self, state0: FloatArray, *, attached0: bool, tau0: float, dtau: float,
                 n_samples: int, substeps: int, settle_periods: int = 0
                 ) -> tuple[FloatArray, FloatArray]:
        """True deflection and rate from ``state0 = [q1, q1', q2, q2']``.

        With ``settle_periods = m`` the run starts ``m`` drive periods before ``tau0`` (same
        drive phase) and the first ``m`` periods are not returned: the output is then the
        model's own attractor reached from ``state0``, not its transient.

        Returns two arrays of shape (n_samples,) (NaN after a blow-up).
        """
        args = self.kernel_args()
        state = np.asarray(state0, float)
        att = bool(attached0)
        if settle_periods > 0:
            period = 2 * math.pi / self.omega
            steps = max(int(round(period / dtau)) * int(substeps), 1)
            _, state, att = simulate_model(state, att, float(tau0) - settle_periods * period,
                                           period, int(settle_periods), steps, *args)
        out, _, _ = simulate_model(state, att, float(tau0), float(dtau), int(n_samples),
                                   int(substeps), *args)
        return out[0], out[1]

    # ------------------------------------------------------------------ text
    def equation(self, *, precision: int = 4) -> str:
        """Dimensionless equation of motion (lengths / L_ref, time omega0 t)."""
        p = precision
        s = self.spec
        K, D, B = (float(v) for v in self.coef[:N_LEVER])
        terms = " ".join(f"{'+' if c >= 0 else '-'} {abs(c):.{p}g} {n}"
                         for c, n in zip(self.force_coefficients, s.term_names(), strict=True))
        ph = s.drive_phase
        eq = (f"x'' + {D:.{p}g} x' + {K:.{p}g} x = -F_ts + {B:.{p}g} cos({self.omega:.{p}g} tau"
              f" {'-' if ph >= 0 else '+'} {abs(ph):.{p}g});  F_ts = {terms.lstrip('+ ')};  z = "
              f"{self.gap:.{p}g} - x, a0 = {s.a0:.{p}g}")
        # one clause per role of the kernel (spec module docstring)
        if s.neck is not None:
            eq += f", neck breaks at z = a0 + {s.neck.neck_length():.{p}g}"
        if s.extra_mode is not None:
            ratio, q2, g2 = s.extra_mode.mode_parameters()
            eq += (f";  mode 2: q2'' + {ratio / q2:.{p}g} q2' + {ratio**2:.{p}g} q2 = "
                   f"{g2:.{p}g} (drive - F_ts), x = q1 + q2 (f2/f0 = {ratio:.{p}g}, "
                   f"Q2 = {q2:.{p}g})")
        if s.output_map is not None:
            eq += ";  measured y = x" + "".join(
                f" {b:+.{p}g} x^{k}" for k, b in enumerate(s.output_map.polynomial(), start=2))
        return eq

    def parameters(self) -> dict[str, Any]:
        """Every fitted parameter, dimensionless and (where it has units) SI."""
        s = self.spec
        sc = self.scales
        L = sc.length
        out: dict[str, Any] = {
            "K": float(self.coef[0]), "D": float(self.coef[1]),
            "Q": float(1.0 / self.coef[1]) if self.coef[1] > 0 else math.inf,
            "B": float(self.coef[2]), "drive_phase_rad": s.drive_phase,
            "a0": s.a0, "a0_m": s.a0 * L, "contact_exponent": s.contact_exponent,
            "coefficients": {n: float(c) for n, c in zip(s.term_names(),
                                                        self.force_coefficients, strict=True)},
        }
        for e in s.extensions:
            out.update(e.report(sc))
        return out
