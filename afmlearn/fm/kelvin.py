"""The Kelvin parabola at each piezo position: ``Δf(V) = a (V - V_cpd)**2 + c``.

The electrostatic force between conductors is ``-(1/2) dC/dz (V - V_cpd)**2``, so at a fixed
position the frequency shift is a parabola in the bias whose vertex is the contact potential
difference (independent of any force law). Its spread over positions is the model-free check
of the joint fit's single ``V_cpd``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from afmlearn.io.instruments.fm_table import FMSpectroscopy

__all__ = ["kelvin_parabolas"]


def kelvin_parabolas(spec: FMSpectroscopy) -> dict[str, NDArray[np.float64]]:
    """Least-squares parabola in ``V`` at every row of the map.

    Returns
    -------
    dict of str -> ndarray, each shape (n_z,)
        ``vcpd_v`` vertex [V] (NaN where the curvature is not negative: no electrostatic
        attraction resolved), ``vcpd_se_v`` its standard error [V] (delta method),
        ``curvature_hz_per_v2`` ``a`` [Hz/V**2], ``vertex_hz`` ``c`` [Hz], ``rms_hz`` the
        residual RMS [Hz].
    """
    v = spec.bias_v
    if v.size < 4:
        raise ValueError(f"spec: a parabola per row needs >= 4 bias columns, got {v.size}")
    x = np.column_stack([v**2, v, np.ones_like(v)])
    coef, *_ = np.linalg.lstsq(x, spec.frequency_shift_hz.T, rcond=None)  # (3, n_z)
    fit = x @ coef
    resid = spec.frequency_shift_hz.T - fit
    dof = max(v.size - 3, 1)
    s2 = np.sum(resid**2, axis=0) / dof
    cov_unit = np.linalg.inv(x.T @ x)
    a, b, c = coef
    vcpd = -b / (2.0 * a)
    # gradient of -b/(2a) w.r.t. (a, b)
    ga, gb = b / (2.0 * a**2), -1.0 / (2.0 * a)
    var = s2 * (ga**2 * cov_unit[0, 0] + gb**2 * cov_unit[1, 1] + 2 * ga * gb * cov_unit[0, 1])
    ok = a < 0
    return {"vcpd_v": np.where(ok, vcpd, np.nan), "vcpd_se_v": np.where(ok, np.sqrt(var), np.nan),
            "curvature_hz_per_v2": a, "vertex_hz": c - b**2 / (4.0 * a),
            "rms_hz": np.sqrt(np.mean(resid**2, axis=0))}
