"""The one compiled integrator: fixed-step RK4 with located force switches.

Used by the simulator (:class:`~simulator.integrate.RK4`), by the identifier's model
simulation (``afmlearn.identify._simulate``) and by the diagnosis' shooting and held-out runs
(``afmlearn.diagnose._kernel``). The force is a :class:`~simulator.forces.law.ForceLaw`
evaluated by :func:`simulator.forces._kernel.law_force`.

State per trajectory: modal deflections ``q`` and velocities ``v`` (``M`` modes), the regime
``r`` and five work integrals, all dimensionless. ``r`` is 0 (free), 1 (contact, attached) or
2 (attached beyond ``a0``: a neck that has not broken yet; only with ``geometric``, below).
Contact-gated terms read ``contact = r != 0`` and the hysteretic ones ``attached = r != 0``
(a JKR contact persists to its break), unless ``geometric``. The gap is
``z = g0 + g' (tau - tau_0) - sum_i q_i - y_b sin(theta)`` and mode ``i`` obeys
``q_i'' = dc_i cos(theta) + ds_i sin(theta) - D_i q_i' - K_i q_i - S_i F``,
``theta = theta_0 + Omega (tau - tau_0)`` (tip or base excitation, 1--3 modes, an approach
ramp). Force switches (contact onset ``z = a0`` either way; the neck or JKR break at
``z = a0 + break_distance``) are located inside the step: cubic Hermite interpolant of the gap,
then Newton on the RK4 sub-step, so the state after a switch depends smoothly on the state
before it (as Newton shooting needs) and the step is split there. Between events the stage at
the end of a step is reused as the first stage of the next (FSAL), so a regular step costs four
force evaluations.

Options (per call):

* ``locate`` -- locate the switches (off: the regime never changes and contact-gated terms
  read ``z <= a0`` at every stage, the identifier's plain fixed-step RK4);
* ``geometric`` -- contact-gated terms read ``z <= a0`` at every stage instead of the carried
  regime (the identifier's and the diagnosis' force convention; the regime then only carries
  the neck);
* ``grade`` -- graded steps at singular switches (below);
* ``blowup`` -- a run whose ``|q_i|`` exceeds it ends in a NaN state and its output from the
  interval that blew up on is NaN (checked after the run).

Contact laws are weakly singular at the switch (``delta**1.5`` for Hertz, ``sqrt(delta)
delta'`` for Kelvin--Voigt, ``sqrt(delta - delta_c)`` at a JKR neck), which would cut RK4's
local error to ``O(h**1.5 .. h**2.5)``. With ``grade`` the steps are graded geometrically on
the singular side of each switch: after entering contact the step grows as
``max(GRADE_MIN h, GRADE_RATIO * (tau - tau_event))`` until it reaches ``h``; while moving
out of contact the step shrinks the same way with the estimated time to the switch
(``(z_switch - z) / z'``), and the partial step that ends on the switch is graded too. This
costs some 60--80 extra steps per contact and removes most of the error constant.

Speed (``docs/benchmarks.md``, "Integrator throughput"): the step loop :func:`_integrate` runs
without numba's reference counting (``_nrt=False``; :func:`integrate_one` only allocates the
buffers around it) and the whole RK4 step with its force evaluations is inlined into it. With
reference counting on, numba increfs/decrefs the array arguments of every inlined call at every
step, and an out-of-line RK4 step spent about a third of its time copying ~15 array structs
onto the stack for the call; together they made a step ~1.6x slower. The rare switch location
(:func:`_switch`, which steps through :func:`_rk4_call`, an out-of-line copy that keeps the cold
compile shorter) and the crossing solve past its quick reject (:func:`_crossing_solve`) stay
out of line. Calls that are not inlined should take at most 30 arguments: CPython passes a call
with more as ``*args`` and numba then builds a tuple of all of them at every call.

Work integrals (``W``): 0 drive input ``int sum_i drive_i v_i``, 1 cantilever damping
``int sum_i D_i v_i**2``, 2 work done on the tip--sample force ``int F sum_i s_i v_i``,
3 energy delivered to the sample ``-int F z'``, 4 time in contact (``r != 0``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..forces._kernel import law_force

N_WORK = 5
MAX_EVENTS_PER_STEP = 16
EVENT_TOL = 1e-13
#: graded steps near a contact switch: step = max(GRADE_MIN h, GRADE_RATIO * distance)
GRADE_RATIO = 0.25
GRADE_MIN = 1e-3
#: regimes
FREE, CONTACT, NECK = 0, 1, 2
#: law header (``ForceLaw.header``): a0, has_contact, break_distance, gates_on_contact
H_A0, H_CONTACT, H_BREAK, H_GATES = 0, 1, 2, 3


@njit(cache=True, inline="always", _nrt=False)
def _rhs(q, v, M, tau, c, s, r, K, Dair, Dcon, S, dc, ds, yb, om, g0, gr, kinds, p1, p2, cf,
         a0, geometric, aq, pw):
    """Accelerations into ``aq`` and work rates into ``pw``; returns (z, zdot, F)."""
    x = 0.0
    xd = 0.0
    for i in range(M):
        x += q[i]
        xd += v[i]
    z = g0 + gr * tau - x - yb * s
    zd = gr - xd - yb * om * c
    contact = z <= a0 if geometric else r != FREE
    f = law_force(kinds, p1, p2, cf, a0, z, zd, x, contact, r != FREE)
    p_drive = 0.0
    p_damp = 0.0
    p_ts = 0.0
    for i in range(M):
        drive = dc[i] * c + ds[i] * s
        d = Dcon[i] if r != FREE else Dair[i]
        aq[i] = drive - d * v[i] - K[i] * q[i] - S[i] * f
        p_drive += drive * v[i]
        p_damp += d * v[i] * v[i]
        p_ts += S[i] * f * v[i]
    pw[0] = p_drive
    pw[1] = p_damp
    pw[2] = p_ts
    pw[3] = -f * zd
    pw[4] = 1.0 if r != FREE else 0.0
    return z, zd, f


@njit(cache=True, inline="always", _nrt=False)
def _gap(q, v, M, tau, c, s, yb, om, g0, gr):
    x = 0.0
    xd = 0.0
    for i in range(M):
        x += q[i]
        xd += v[i]
    return g0 + gr * tau - x - yb * s, gr - xd - yb * om * c


@njit(cache=True, inline="always", _nrt=False)
def _rk4(q, v, W, M, tau, h, cm, sm, c1, s1, r, mp, yb, om, g0, gr, kinds, p1, p2, cf, a0,
         geometric, a1, pa, qn, vn, Wn, wk, pk):
    """One classical RK4 step of length ``h`` for ``q' = v, v' = a(q, v, tau)``.

    ``(a1, pa)`` is the first stage at ``(q, v, tau)``; drive cos/sin at the midpoint and the
    end are passed in. The new state goes to ``(qn, vn, Wn)``. ``wk`` (8, M) and ``pk``
    (3, N_WORK) are scratch buffers. ``mp`` (6, M) holds the modal ``K, Dair, Dcon, S, dc,
    ds``. Inlined (module docstring, "Speed").
    """
    K = mp[0]
    Dair = mp[1]
    Dcon = mp[2]
    S = mp[3]
    dc = mp[4]
    ds = mp[5]
    h2 = 0.5 * h
    qs = wk[0]
    v2 = wk[1]
    v3 = wk[2]
    v4 = wk[3]
    a2 = wk[4]
    a3 = wk[5]
    a4 = wk[6]
    for i in range(M):
        qs[i] = q[i] + h2 * v[i]
        v2[i] = v[i] + h2 * a1[i]
    _rhs(qs, v2, M, tau + h2, cm, sm, r, K, Dair, Dcon, S, dc, ds, yb, om, g0, gr, kinds, p1,
         p2, cf, a0, geometric, a2, pk[0])
    for i in range(M):
        qs[i] = q[i] + h2 * v2[i]
        v3[i] = v[i] + h2 * a2[i]
    _rhs(qs, v3, M, tau + h2, cm, sm, r, K, Dair, Dcon, S, dc, ds, yb, om, g0, gr, kinds, p1,
         p2, cf, a0, geometric, a3, pk[1])
    for i in range(M):
        qs[i] = q[i] + h * v3[i]
        v4[i] = v[i] + h * a3[i]
    _rhs(qs, v4, M, tau + h, c1, s1, r, K, Dair, Dcon, S, dc, ds, yb, om, g0, gr, kinds, p1,
         p2, cf, a0, geometric, a4, pk[2])
    h6 = h / 6.0
    for i in range(M):
        qn[i] = q[i] + h6 * (v[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i])
        vn[i] = v[i] + h6 * (a1[i] + 2.0 * a2[i] + 2.0 * a3[i] + a4[i])
    for j in range(N_WORK):
        Wn[j] = W[j] + h6 * (pa[j] + 2.0 * pk[0, j] + 2.0 * pk[1, j] + pk[2, j])


@njit(cache=True, _nrt=False)
def _rk4_call(q, v, W, M, tau, h, cm, sm, c1, s1, r, mp, yb, om, g0, gr, kinds, p1, p2, cf, a0,
              geometric, a1, pa, qn, vn, Wn, wk, pk):
    """:func:`_rk4` out of line, for the rare paths (:func:`_switch`, :func:`_graded_to_end`):
    one more inlined copy of the step would only lengthen the cold compile."""
    _rk4(q, v, W, M, tau, h, cm, sm, c1, s1, r, mp, yb, om, g0, gr, kinds, p1, p2, cf, a0,
         geometric, a1, pa, qn, vn, Wn, wk, pk)


@njit(cache=True, inline="always", _nrt=False)
def _hermite(t, e0, e1, d0, d1):
    a = 2.0 * e0 + d0 - 2.0 * e1 + d1
    b = -3.0 * e0 - 2.0 * d0 + 3.0 * e1 - d1
    return ((a * t + b) * t + d0) * t + e0


@njit(cache=True, inline="always", _nrt=False)
def _below(t, e0, e1, d0, d1, sgn):
    return sgn * _hermite(t, e0, e1, d0, d1) < -EVENT_TOL


@njit(cache=True, _nrt=False)
def _bisect(lo, hi, e0, e1, d0, d1, sgn):
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if sgn * _hermite(mid, e0, e1, d0, d1) < 0.0:
            hi = mid
        else:
            lo = mid
        if hi - lo < 1e-15:
            break
    return hi


@njit(cache=True, inline="always", _nrt=False)
def _first_crossing(e0, e1, d0, d1, sgn):
    """First ``t`` in (0, 1] where ``sgn * e(t) < -EVENT_TOL`` on the Hermite cubic, or -1.

    ``e0, e1`` are the event function at the ends, ``d0, d1`` its derivatives times the step.
    A conservative bound rejects most steps without solving anything (inlined; the solve is
    :func:`_crossing_solve`): ``e(t) >= min(e0, e1) - max(|d0 - De|, |d1 - De|) / 4`` with
    ``De = e1 - e0``.
    """
    de = e1 - e0
    dev = 0.25 * max(abs(d0 - de), abs(d1 - de))
    if min(sgn * e0, sgn * e1) - dev > 0.0:
        return -1.0
    return _crossing_solve(e0, e1, d0, d1, sgn)


@njit(cache=True, _nrt=False)
def _crossing_solve(e0, e1, d0, d1, sgn):
    """:func:`_first_crossing` past its quick reject (the cubic's extrema, then bisection)."""
    u1 = sgn * e1
    a = 2.0 * e0 + d0 - 2.0 * e1 + d1
    b = -3.0 * e0 - 2.0 * d0 + 3.0 * e1 - d1
    t1 = 2.0
    t2 = 2.0
    if a != 0.0:
        disc = b * b - 3.0 * a * d0
        if disc >= 0.0:
            r = math.sqrt(disc)
            t1 = (-b - r) / (3.0 * a)
            t2 = (-b + r) / (3.0 * a)
            if t1 > t2:
                t1, t2 = t2, t1
    elif b != 0.0:
        t1 = -d0 / (2.0 * b)
    lo = 0.0
    if 0.0 < t1 < 1.0:
        if _below(t1, e0, e1, d0, d1, sgn):
            return _bisect(lo, t1, e0, e1, d0, d1, sgn)
        lo = t1
    if 0.0 < t2 < 1.0:
        if _below(t2, e0, e1, d0, d1, sgn):
            return _bisect(lo, t2, e0, e1, d0, d1, sgn)
        lo = t2
    if u1 < -EVENT_TOL:
        return _bisect(lo, 1.0, e0, e1, d0, d1, sgn)
    return -1.0


@njit(cache=True, _nrt=False)
def _graded_to_end(q, v, W, M, tau, length, hmin, r, mp, yb, om, g0, gr, th0, kinds, p1, p2,
                   cf, a0, geometric, a1, pa, qe, ve, We, qg, vg, Wg, ag, pg, wk, pk):
    """Integrate from (q, v, W) at ``tau`` over ``length`` with steps shrinking geometrically
    towards the end (a singular point of the force); result in (qe, ve, We).

    ``(a1, pa)`` is the first stage at the start (not modified).
    """
    for i in range(M):
        qg[i] = q[i]
        vg[i] = v[i]
        ag[i] = a1[i]
    for j in range(N_WORK):
        Wg[j] = W[j]
        pg[j] = pa[j]
    t = 0.0
    while True:
        d = length - t
        if d <= hmin:
            step = d
        else:
            step = max(hmin, GRADE_RATIO * d)
        thm = th0 + om * (tau + t + 0.5 * step)
        th1 = th0 + om * (tau + t + step)
        c1 = math.cos(th1)
        s1 = math.sin(th1)
        _rk4_call(qg, vg, Wg, M, tau + t, step, math.cos(thm), math.sin(thm), c1, s1, r, mp, yb,
                  om, g0, gr, kinds, p1, p2, cf, a0, geometric, ag, pg, qe, ve, We, wk, pk)
        t += step
        if step == d:
            return
        for i in range(M):
            qg[i] = qe[i]
            vg[i] = ve[i]
        for j in range(N_WORK):
            Wg[j] = We[j]
        _rhs(qg, vg, M, tau + t, c1, s1, r, mp[0], mp[1], mp[2], mp[3], mp[4], mp[5], yb, om, g0,
             gr, kinds, p1, p2, cf, a0, geometric, ag, pg)


@njit(cache=True, _nrt=False)
def _switch(q, v, W, M, tau, hs, hh, zsw, hmin, r, r_new, mp, yb, om, g0, gr, th0, kinds, p1,
            p2, cf, a0, geometric, grade, a1, pa, qe, ve, We, qg, vg, Wg, ag, pg, wk, pk):
    """Step from ``tau`` onto the switch ``z = zsw`` found at ``tau + hs`` (``hs < hh``) and
    enter regime ``r_new``: Newton on the RK4 sub-step, the state (q, v, W) and the first stage
    (a1, pa) updated in place; returns ``(tau, cos, sin, z, z', F)`` after the switch.

    Out of line: a rare branch, and a smaller step loop in :func:`_integrate` ran faster.
    """
    for _it in range(4):
        th1 = th0 + om * (tau + hs)
        c1e = math.cos(th1)
        s1e = math.sin(th1)
        if grade and r == CONTACT:
            # leaving contact: the force is singular at the switch
            _graded_to_end(q, v, W, M, tau, hs, hmin, r, mp, yb, om, g0, gr, th0, kinds, p1, p2,
                           cf, a0, geometric, a1, pa, qe, ve, We, qg, vg, Wg, ag, pg, wk, pk)
        else:
            thm = th0 + om * (tau + 0.5 * hs)
            _rk4_call(q, v, W, M, tau, hs, math.cos(thm), math.sin(thm), c1e, s1e, r, mp, yb, om,
                      g0, gr, kinds, p1, p2, cf, a0, geometric, a1, pa, qe, ve, We, wk, pk)
        ze, zde = _gap(qe, ve, M, tau + hs, c1e, s1e, yb, om, g0, gr)
        err = ze - zsw
        if abs(err) < 1e-14 or zde == 0.0:
            break
        hn = hs - err / zde
        if hn <= 0.0 or hn > hh:
            break
        hs = hn
    for i in range(M):
        q[i] = qe[i]
        v[i] = ve[i]
    for j in range(N_WORK):
        W[j] = We[j]
    tau = tau + hs
    z, zd, f = _rhs(q, v, M, tau, c1e, s1e, r_new, mp[0], mp[1], mp[2], mp[3], mp[4], mp[5], yb,
                    om, g0, gr, kinds, p1, p2, cf, a0, geometric, a1, pa)
    return tau, c1e, s1e, z, zd, f


@njit(cache=True, inline="always", _nrt=False)
def _leave_surface(r, a0, brk, gates):
    """Gap at which regime ``r`` (1 or 2) is left outward, and the regime after it."""
    if r == CONTACT:
        if brk == 0.0:
            return a0, FREE
        if gates:
            return a0, NECK
    return a0 + brk, FREE


@njit(cache=True)
def integrate_one(q, v, W, r, th0, om, dc, ds, yb, g0, gr, K, Dair, Dcon, S, kinds, p1, p2, cf,
                  hdr, dt, n_samples, substeps, locate, geometric, grade, blowup, q_out, v_out,
                  f_out, c_out, record_velocity):
    """Integrate one trajectory over ``n_samples`` output samples; returns the final regime.

    Parameters
    ----------
    q, v : float64 (M,)
        Modal state at the start (updated in place to the end state; NaN after a blow-up).
    W : float64 (N_WORK,)
        Work integrals (accumulated in place).
    r : int
        Regime at the start (0 free, 1 contact, 2 neck).
    th0, om : float
        Drive phase at the start and drive frequency; time is kept relative to the start and
        recomputed exactly at every sub-step boundary, so long runs do not drift the phase.
    dc, ds : float64 (M,)
        Modal drive ``dc cos(theta) + ds sin(theta)``.
    yb : float
        Base-motion amplitude entering the gap.
    g0, gr : float
        Rest gap at the start and its rate (approach ramp).
    K, Dair, Dcon, S : float64 (M,)
        Modal stiffness, damping out of/in contact, force gains.
    kinds, p1, p2, cf : (n_terms,)
        The force law's terms (``ForceLaw.arrays``).
    hdr : float64 (4,)
        ``ForceLaw.header()``.
    dt : float
        Output sample interval; the step is ``dt / substeps``.
    locate, geometric, grade : bool; blowup : float
        Options (module docstring).
    q_out : float64 (M, n_samples); v_out : float64 (M, n_samples) or (M, 0)
    f_out : float64 (n_samples,); c_out : int8 (n_samples,)
        Recorded at ``k dt``, k = 0 .. n_samples - 1 (before each interval).
    """
    M = q.shape[0]
    mp = np.empty((6, M))  # modal parameters, one argument for _rk4 (see there)
    for i in range(M):
        mp[0, i] = K[i]
        mp[1, i] = Dair[i]
        mp[2, i] = Dcon[i]
        mp[3, i] = S[i]
        mp[4, i] = dc[i]
        mp[5, i] = ds[i]
    r = _integrate(q, v, W, r, th0, om, yb, g0, gr, kinds, p1, p2, cf, hdr, dt, n_samples,
                   substeps, locate, geometric, grade, q_out, v_out, f_out, c_out,
                   record_velocity, mp, np.empty((9, M)), np.empty((6, N_WORK)),
                   np.empty((8, M)), np.empty((3, N_WORK)))
    if blowup < np.inf:
        _blown(q, v, q_out, blowup, 0, n_samples, f_out, v_out, record_velocity)
    return r


@njit(cache=True, _nrt=False)
def _integrate(q, v, W, r, th0, om, yb, g0, gr, kinds, p1, p2, cf, hdr, dt, n_samples, substeps,
               locate, geometric, grade, q_out, v_out, f_out, c_out, record_velocity, mp, bm, bw,
               wk, pk):
    """The step loop of :func:`integrate_one` (same arguments; ``mp`` (6, M) the modal
    parameters packed, ``bm`` (9, M), ``bw`` (6, N_WORK), ``wk`` (8, M) and ``pk``
    (3, N_WORK) scratch buffers); returns the final regime.

    Without reference counting (``_nrt=False``), so that the inlined RK4 step and force
    evaluations cost no incref/decref per step (module docstring, "Speed").
    """
    M = q.shape[0]
    h = dt / substeps
    a0 = hdr[H_A0]
    has_contact = locate and hdr[H_CONTACT] != 0.0
    brk = hdr[H_BREAK]
    # a separate neck regime only where contact-gated terms read the gap (else r is 0 or 1)
    gates = geometric and hdr[H_GATES] != 0.0
    tau = 0.0
    K = mp[0]
    Dair = mp[1]
    Dcon = mp[2]
    S = mp[3]
    dc = mp[4]
    ds = mp[5]
    a1 = bm[0]
    an = bm[1]
    qn = bm[2]
    vn = bm[3]
    qe = bm[4]
    ve = bm[5]
    qg = bm[6]
    vg = bm[7]
    ag = bm[8]
    pa = bw[0]
    pn = bw[1]
    Wg = bw[2]
    pg = bw[3]
    Wn = bw[4]
    We = bw[5]
    hmin = GRADE_MIN * h
    grade_span = h / GRADE_RATIO if grade else -1.0
    tau_ev = -1e300  # time of the last entry into contact
    chh = math.cos(0.5 * om * h)
    shh = math.sin(0.5 * om * h)
    th = th0
    c = math.cos(th)
    s = math.sin(th)
    z, zd, f = _rhs(q, v, M, tau, c, s, r, K, Dair, Dcon, S, dc, ds, yb, om, g0, gr, kinds, p1,
                    p2, cf, a0, geometric, a1, pa)
    for k in range(n_samples):
        for i in range(M):
            q_out[i, k] = q[i]
        if record_velocity:
            for i in range(M):
                v_out[i, k] = v[i]
        f_out[k] = f
        c_out[k] = r
        # drive cos/sin advance by rotation; re-synchronised exactly every 64 samples
        if k % 64 == 0:
            th = th0 + om * (k * dt)
            c = math.cos(th)
            s = math.sin(th)
        for _sub in range(substeps):
            tau = (k * substeps + _sub) * h
            t_end = tau + h
            n_ev = 0
            fresh = True  # nothing integrated yet in this sub-step: hh == h exactly
            while True:
                hh = t_end - tau
                if hh <= 0.0:
                    break
                full = True
                if grade:
                    dist = tau - tau_ev
                    if r == CONTACT and zd > 0.0:
                        # approaching the switch out of contact: estimated time to it
                        zl, _ = _leave_surface(r, a0, brk, gates)
                        dist = min(dist, (zl - z) / zd)
                    if dist < grade_span:
                        gh = max(hmin, GRADE_RATIO * max(dist, 0.0))
                        if gh < hh:
                            hh = gh
                            full = False
                if full and fresh:
                    cm = c * chh - s * shh
                    sm = s * chh + c * shh
                    c1 = cm * chh - sm * shh
                    s1 = sm * chh + cm * shh
                else:
                    thm = th0 + om * (tau + 0.5 * hh)
                    th1 = th0 + om * (tau + hh)
                    cm = math.cos(thm)
                    sm = math.sin(thm)
                    c1 = math.cos(th1)
                    s1 = math.sin(th1)
                _rk4(q, v, W, M, tau, hh, cm, sm, c1, s1, r, mp, yb, om, g0, gr, kinds, p1, p2, cf,
                     a0, geometric, a1, pa, qn, vn, Wn, wk, pk)
                z1, zd1, f1 = _rhs(qn, vn, M, tau + hh, c1, s1, r, K, Dair, Dcon, S, dc, ds, yb,
                                   om, g0, gr, kinds, p1, p2, cf, a0, geometric, an, pn)
                fresh = False
                t_ev = -1.0
                zsw = 0.0
                r_new = r
                if has_contact and n_ev < MAX_EVENTS_PER_STEP:
                    if r == FREE or r == NECK:
                        t_ev = _first_crossing(z - a0, z1 - a0, zd * hh, zd1 * hh, 1.0)
                        zsw = a0
                        r_new = CONTACT
                    if r != FREE:
                        zl, rl = _leave_surface(r, a0, brk, gates)
                        tl = _first_crossing(z - zl, z1 - zl, zd * hh, zd1 * hh, -1.0)
                        if tl >= 0.0 and (t_ev < 0.0 or tl < t_ev):
                            t_ev = tl
                            zsw = zl
                            r_new = rl
                if t_ev < 0.0:
                    for i in range(M):
                        q[i] = qn[i]
                        v[i] = vn[i]
                        a1[i] = an[i]
                    for j in range(N_WORK):
                        W[j] = Wn[j]
                        pa[j] = pn[j]
                    tau = tau + hh
                    c = c1
                    s = s1
                    z = z1
                    zd = zd1
                    f = f1
                    if full:
                        break
                    continue
                # ---- event: locate it on the RK4 map, switch regime, continue
                n_ev += 1
                tau, c, s, z, zd, f = _switch(
                    q, v, W, M, tau, t_ev * hh, hh, zsw, hmin, r, r_new, mp, yb, om, g0, gr, th0,
                    kinds, p1, p2, cf, a0, geometric, grade, a1, pa, qe, ve, We, qg, vg, Wg, ag,
                    pg, wk, pk)
                r = r_new
                if r == CONTACT:
                    tau_ev = tau
            # after a graded or split step, c and s are exact at tau
    return r


@njit(cache=True, _nrt=False)
def _blown(q, v, q_out, blowup, k0, k, f_out, v_out, record_velocity):
    """Blow-up check after a run (an exit from the sample loop costs ~40 % of a step).

    The state at sample ``j`` is ``q_out[:, j]`` (``j < k``) or ``q`` (``j = k``). If one in
    ``(k0, k]`` has ``|q_i| >= blowup`` (or NaN), the output from sample ``j - 1`` on (the
    interval that blew up) is set to NaN, as are ``q`` and ``v``; returns True.
    """
    M = q.shape[0]
    ok = True
    for i in range(M):
        if not abs(q[i]) < blowup:
            ok = False
    if ok:
        return False
    first = k
    for j in range(max(k0 + 1, 1), k):
        bad = False
        for i in range(M):
            if not abs(q_out[i, j]) < blowup:
                bad = True
        if bad:
            first = j
            break
    n = f_out.shape[0]
    for kk in range(first - 1, n):
        f_out[kk] = math.nan
        for i in range(M):
            q_out[i, kk] = math.nan
            if record_velocity:
                v_out[i, kk] = math.nan
    for i in range(M):
        q[i] = math.nan
        v[i] = math.nan
    return True


@njit(cache=True, parallel=True)
def integrate_segment(q0, v0, regime0, tau0, theta0, omega, dc, ds, ybase, g0, grate, K,
                      Dair, Dcon, S, kinds, p1, p2, cf, hdr, W, dt, n_samples, substeps,
                      q_out, v_out, f_out, c_out, record_velocity):
    """Integrate ``B`` trajectories (the simulator's batch) over ``n_samples``, in place.

    Parameters
    ----------
    q0, v0 : float64 (B, M)
        Modal state at the segment start (updated to the end state).
    regime0 : int8 (B,)
        Regime (updated).
    tau0 : float64 (B,)
        Start time (updated to the end time).
    theta0 : float64 (B,)
        Drive phase at ``tau0`` (updated, wrapped to [0, 2 pi)).
    omega : float64 (B,)
        Drive frequency.
    dc, ds : float64 (B, M)
        Modal drive ``dc cos(theta) + ds sin(theta)``.
    ybase : float64 (B,)
        Base-motion amplitude entering the gap.
    g0, grate : float64 (B,)
        Rest gap at ``tau0`` (updated) and its rate (approach ramp).
    K, Dair, Dcon, S : float64 (B, M)
        Modal stiffness, damping out of/in contact, force gains.
    kinds, p1, p2, cf : (B, T)
        Force laws, zero-padded (``simulator.forces.law.pack_laws``).
    hdr : float64 (B, 4)
        Law headers.
    W : float64 (B, N_WORK)
        Work integrals (accumulated).
    dt : float
        Output sample interval; the step is ``dt / substeps``.
    q_out : float64 (B, M, n_samples); v_out : float64 (B, M, n_samples) or (B, M, 0)
    f_out : float64 (B, n_samples); c_out : int8 (B, n_samples)
        Recorded at ``tau0 + k dt``, k = 0 .. n_samples - 1 (before each interval).
    """
    B = q0.shape[0]
    for b in prange(B):
        q = q0[b].copy()
        v = v0[b].copy()
        Wb = W[b].copy()
        r = integrate_one(q, v, Wb, np.int64(regime0[b]), theta0[b], omega[b], dc[b], ds[b],
                          ybase[b], g0[b], grate[b], K[b], Dair[b], Dcon[b], S[b], kinds[b],
                          p1[b], p2[b], cf[b], hdr[b], dt, n_samples, substeps, True, False,
                          True, np.inf, q_out[b], v_out[b], f_out[b], c_out[b],
                          record_velocity)
        for i in range(q.shape[0]):
            q0[b, i] = q[i]
            v0[b, i] = v[i]
        for j in range(N_WORK):
            W[b, j] = Wb[j]
        regime0[b] = r
        t_total = n_samples * dt
        theta0[b] = (theta0[b] + omega[b] * t_total) % (2.0 * math.pi)
        g0[b] = g0[b] + grate[b] * t_total
        tau0[b] = tau0[b] + t_total
