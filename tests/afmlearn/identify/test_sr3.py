"""BoxSR3 against pysindy (cases pysindy supports), cvxpy (box cases) and known systems."""

from __future__ import annotations

import itertools
import warnings

import cvxpy as cp
import numpy as np
import pysindy as ps
import pytest
from scipy.integrate import solve_ivp

from afmlearn.identify.optimizers import BoxSR3, InfeasibleError, constrained_lstsq


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        warnings.simplefilter("ignore", DeprecationWarning)
        yield


def _sparse_problem(seed=0, n=300, p=8, T=1, noise=0.05):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, p))
    X[:, 1] += 0.5 * X[:, 0]  # some collinearity
    xi = np.zeros((T, p))
    for t in range(T):
        idx = rng.choice(p, 3, replace=False)
        xi[t, idx] = rng.choice([-1, 1], 3) * rng.uniform(0.4, 2.0, 3)
    Y = X @ xi.T + noise * rng.normal(size=(n, T))
    return X, (Y[:, 0] if T == 1 else Y), xi


def _cvx_lstsq(X, y, support, lower, upper, C=None, d=None):
    """Reference: box/equality-constrained least squares on a support with cvxpy."""
    p = X.shape[1]
    c = cp.Variable(p)
    cons = [c[~support] == 0]
    fin_lo, fin_hi = np.isfinite(lower), np.isfinite(upper)
    if fin_lo.any():
        cons.append(c[fin_lo] >= lower[fin_lo])
    if fin_hi.any():
        cons.append(c[fin_hi] <= upper[fin_hi])
    if C is not None:
        cons.append(C @ c == d)
    cp.Problem(cp.Minimize(cp.sum_squares(X @ c - y)), cons).solve(solver=cp.CLARABEL)
    return c.value


@pytest.mark.parametrize(("threshold", "nu", "unbias"),
                         [(0.1, 0.01, False), (0.5, 0.01, False), (0.3, 1.0, False),
                          (0.3, 1.0, True), (0.8, 0.1, True)])
def test_matches_pysindy_sr3_l0(threshold, nu, unbias):
    X, y, _ = _sparse_problem(seed=1)
    ref = ps.SR3(reg_weight_lam=ps.SR3.calculate_l0_weight(threshold, nu), relax_coeff_nu=nu,
                 max_iter=200, tol=1e-12, unbias=unbias).fit(X, y)
    ours = BoxSR3(threshold, nu, max_iter=200, tol=1e-12, unbias=unbias).fit(X, y)
    assert ours.coef_.shape == ref.coef_.shape == (1, X.shape[1])
    np.testing.assert_allclose(ours.coef_, ref.coef_, atol=1e-9)
    np.testing.assert_array_equal(ours.ind_, np.abs(ref.coef_) > 0 if not unbias else ref.ind_)
    assert ours.n_iter_ == len(ref.history_) - 1
    np.testing.assert_allclose(ours.history_[0], ref.history_[0], atol=1e-9)


@pytest.mark.parametrize("order", ["target", "feature"])
@pytest.mark.parametrize("nu", [0.05, 1.0])
def test_matches_pysindy_constrained_sr3_equality(order, nu):
    X, Y, _ = _sparse_problem(seed=2, p=6, T=2)
    T, p = 2, 6
    C = np.zeros((2, T * p))  # target order
    C[0, 0] = 1.0
    C[1, p + 1], C[1, p + 3] = 1.0, 1.0
    d = np.array([1.1, 2.0])
    Cu = C if order == "target" else C.reshape(2, T, p).transpose(0, 2, 1).reshape(2, -1)
    thr = 0.2
    ref = ps.ConstrainedSR3(reg_weight_lam=thr**2 / (2 * nu), relax_coeff_nu=nu, max_iter=300,
                            tol=1e-12, constraint_lhs=Cu.copy(), constraint_rhs=d,
                            constraint_order=order, equality_constraints=True).fit(X, Y)
    ours = BoxSR3(thr, nu, constraint_lhs=Cu, constraint_rhs=d, constraint_order=order,
                  max_iter=300, tol=1e-12, unbias=False).fit(X, Y)
    np.testing.assert_allclose(ours.coef_, ref.coef_, atol=1e-9)
    np.testing.assert_allclose(ours.coef_full_, ref.coef_full_, atol=1e-9)
    # unbiased: sparse AND exactly on the constraints, and the LS optimum on its support
    ub = BoxSR3(thr, nu, constraint_lhs=Cu, constraint_rhs=d, constraint_order=order,
                max_iter=300, tol=1e-12).fit(X, Y)
    np.testing.assert_allclose(C @ ub.coef_.ravel(), d, atol=1e-10)
    ref_cvx = cp.Variable((T, p))
    supp = ub.coef_ != 0
    prob = cp.Problem(cp.Minimize(cp.sum_squares(X @ ref_cvx.T - Y)),
                      [C @ cp.vec(ref_cvx, order="C") == d, ref_cvx[~supp] == 0])
    prob.solve(solver=cp.CLARABEL)
    np.testing.assert_allclose(ub.coef_, ref_cvx.value, atol=1e-6)


def test_inside_pysindy_sindy():
    """A damped oscillator x' = v, v' = -x - 0.2 v through ps.SINDy with BoxSR3."""
    t = np.linspace(0, 20, 4001)
    sol = solve_ivp(lambda _t, s: [s[1], -s[0] - 0.2 * s[1]], (0, 20), [1.0, 0.0], t_eval=t,
                    rtol=1e-11, atol=1e-12)
    x = sol.y.T
    lib = ps.PolynomialLibrary(degree=2)
    model = ps.SINDy(optimizer=BoxSR3(0.05, 1.0), feature_library=lib)
    model.fit(x, t=t[1] - t[0])
    names = lib.get_feature_names()
    coef = model.coefficients()
    true = np.zeros_like(coef)
    true[0, names.index("x1")] = 1.0
    true[1, names.index("x0")], true[1, names.index("x1")] = -1.0, -0.2
    np.testing.assert_allclose(coef, true, atol=2e-3)
    assert np.array_equal(coef != 0, true != 0)
    assert np.allclose(model.predict(x[:5]), np.column_stack([x[:5, 1],
                                                              -x[:5, 0] - 0.2 * x[:5, 1]]),
                       atol=1e-2)


def test_box_keeps_small_constrained_coefficient():
    """A -1/Q damping coefficient below the threshold survives if its box excludes 0."""
    rng = np.random.default_rng(3)
    n, q = 2000, 100.0
    X = rng.normal(size=(n, 5))
    xi = np.array([-1.0 / q, -1.0, 0.3, 0.0, 0.0])
    y = X @ xi + 1e-3 * rng.normal(size=n)
    thr = 0.05
    plain = BoxSR3(thr, 1.0).fit(X, y)
    assert plain.coef_[0, 0] == 0.0  # thresholded like pysindy would
    lo = np.array([-1.15 / q, -1.15, -np.inf, -np.inf, -np.inf])
    hi = np.array([-0.85 / q, -0.85, np.inf, np.inf, np.inf])
    boxed = BoxSR3(thr, 1.0, lower=lo, upper=hi).fit(X, y)
    np.testing.assert_allclose(boxed.coef_[0], xi, atol=1e-4)


def test_active_box_matches_cvxpy_and_brute_force():
    """True x-coefficient outside its box: result = box-constrained LS on the brute-force
    best support."""
    rng = np.random.default_rng(4)
    n, p = 500, 5
    X = rng.normal(size=(n, p))
    xi = np.array([1.4, 0.0, -0.7, 0.0, 0.25])
    y = X @ xi + 0.02 * rng.normal(size=n)
    lo = np.array([0.85, -np.inf, -np.inf, -np.inf, 0.3])
    hi = np.array([1.15, np.inf, np.inf, np.inf, np.inf])
    opt = BoxSR3(0.1, 0.5, lower=lo, upper=hi).fit(X, y)
    assert np.all(opt.coef_[0] >= lo) and np.all(opt.coef_[0] <= hi)
    # brute force over supports: l0-penalised box-constrained least squares
    pen = 0.5 * n * 0.05**2
    best, best_cost = None, np.inf
    for k in range(p + 1):
        for S in itertools.combinations(range(p), k):
            s = np.zeros(p, bool)
            s[list(S)] = True
            if np.any(~s & ((lo > 0) | (hi < 0))):
                continue  # a box excluding 0 forces the term in
            c = _cvx_lstsq(X, y, s, lo, hi)
            cost = 0.5 * np.sum((X @ c - y) ** 2) + pen * k
            if cost < best_cost:
                best, best_cost = (s, c), cost
    np.testing.assert_array_equal(opt.ind_[0], best[0])
    np.testing.assert_allclose(opt.coef_[0], best[1], atol=1e-6)
    assert opt.coef_[0, 0] == pytest.approx(1.15) and opt.coef_[0, 4] == pytest.approx(0.3)


@pytest.mark.parametrize("seed", range(6))
def test_constrained_lstsq_matches_cvxpy(seed):
    rng = np.random.default_rng(seed)
    n, p = 40, 7
    X = rng.normal(size=(n, p))
    y = rng.normal(size=n) * 3
    lo = np.where(rng.random(p) < 0.6, -rng.uniform(0, 0.3, p), -np.inf)
    hi = np.where(rng.random(p) < 0.6, rng.uniform(0, 0.3, p), np.inf)
    C = rng.normal(size=(2, p)) if seed % 2 else None
    d = (C @ np.clip(rng.normal(size=p) * 0.1, lo, hi)) if C is not None else None
    x = constrained_lstsq(X.T @ X, X.T @ y, lower=lo, upper=hi, A=C, d=d)
    ref = _cvx_lstsq(X, y, np.ones(p, bool), lo, hi, C, d)
    obj = np.sum((X @ x - y) ** 2)
    assert obj <= np.sum((X @ ref - y) ** 2) * (1 + 1e-7)
    np.testing.assert_allclose(x, ref, atol=1e-5)
    assert np.all(x >= lo) and np.all(x <= hi)
    if C is not None:
        np.testing.assert_allclose(C @ x, d, atol=1e-9)


def test_constrained_lstsq_infeasible():
    with pytest.raises(InfeasibleError):
        constrained_lstsq(np.eye(2), np.ones(2), lower=[0, 0], upper=[1, 1],
                          A=[[1.0, 1.0]], d=[3.0])


def test_box_and_equality_together():
    """Box + equality: result meets both and equals cvxpy on the support."""
    rng = np.random.default_rng(5)
    n, p = 400, 6
    X = rng.normal(size=(n, p))
    y = X @ np.array([1.3, -0.5, 0.0, 0.8, 0.0, 0.0]) + 0.05 * rng.normal(size=n)
    lo = np.array([0.85, -np.inf, -np.inf, -np.inf, -np.inf, -np.inf])
    hi = np.array([1.15, np.inf, np.inf, 0.6, np.inf, np.inf])
    C = np.array([[0.0, 1.0, 0.0, 1.0, 0.0, 0.0]])
    d = np.array([0.2])
    opt = BoxSR3(0.1, 0.3, lower=lo, upper=hi, constraint_lhs=C, constraint_rhs=d).fit(X, y)
    c = opt.coef_[0]
    assert np.all(c >= lo) and np.all(c <= hi)
    np.testing.assert_allclose(C @ c, d, atol=1e-10)
    np.testing.assert_allclose(c, _cvx_lstsq(X, y, c != 0, lo, hi, C, d), atol=1e-6)


def test_objective_nonincreasing_with_box():
    """Exact alternating minimisation: the SR3 objective never increases (checks the prox)."""
    X, y, _ = _sparse_problem(seed=6, p=10)
    lo = np.full(10, -0.8)
    hi = np.full(10, 0.9)
    lo[2], hi[2] = 0.05, 0.3  # excludes 0
    opt = BoxSR3(0.3, 0.05, lower=lo, upper=hi, max_iter=100, unbias=False).fit(X, y)
    f = np.array(opt.objective_history_)
    assert np.all(np.diff(f) <= 1e-9 * np.abs(f[:-1]))
    assert opt.coef_[0, 2] != 0.0
    assert np.all(opt.coef_ >= lo) and np.all(opt.coef_ <= hi)


def test_normalize_columns_keeps_constraints_in_original_units():
    rng = np.random.default_rng(7)
    n = 600
    X = rng.normal(size=(n, 4)) * np.array([1e3, 1.0, 1e-2, 1.0])
    xi = np.array([2e-3, -1.0, 30.0, 0.0])
    y = X @ xi + 0.01 * rng.normal(size=n)
    lo = np.array([1e-3, -1.15, -np.inf, -np.inf])
    hi = np.array([1.5e-3, -0.85, np.inf, np.inf])
    C = np.array([[0.0, 0.0, 1.0, 1.0]])
    d = np.array([25.0])
    kw = dict(lower=lo, upper=hi, constraint_lhs=C, constraint_rhs=d, max_iter=500)
    a = BoxSR3(0.5, 1.0, normalize_columns=True, **kw).fit(X, y)
    b = BoxSR3(0.5, 1.0, normalize_columns=False, **kw).fit(X, y)
    for o in (a, b):
        assert np.all(o.coef_[0] >= lo) and np.all(o.coef_[0] <= hi)
        np.testing.assert_allclose(C @ o.coef_[0], d, atol=1e-9)
    # same support -> same unbiased constrained fit
    np.testing.assert_array_equal(a.ind_, b.ind_)
    np.testing.assert_allclose(a.coef_, b.coef_, rtol=1e-7, atol=1e-9)
    assert a.coef_[0, 0] == pytest.approx(1.5e-3)


def test_recovers_driven_duffing_from_noisy_data():
    """x'' = -x - x'/Q + F cos(W t) - 0.3 x^3 from noisy accelerations, with calibration box."""
    q, w, F = 50.0, 1.2, 0.4
    rhs = lambda t, s: [s[1], -s[0] - s[1] / q + F * np.cos(w * t) - 0.3 * s[0] ** 3]  # noqa: E731
    t = np.linspace(0, 250, 25001)
    s = solve_ivp(rhs, (0, 250), [0.2, 0.0], t_eval=t, method="DOP853", rtol=1e-10,
                  atol=1e-12).y
    x, v = s
    acc = np.array(rhs(t, s))[1]
    rng = np.random.default_rng(8)
    y = acc + 0.01 * np.ptp(acc) * rng.normal(size=t.size)
    names = ["v", "x", "cos", "sin", "1", "x^2", "x^3", "x^4", "v x^2", "v^3"]
    Theta = np.column_stack([v, x, np.cos(w * t), np.sin(w * t), np.ones_like(t), x**2, x**3,
                             x**4, v * x**2, v**3])
    lo = np.full(len(names), -np.inf)
    hi = np.full(len(names), np.inf)
    lo[:3], hi[:3] = [-1.15 / q, -1.15, 0.85 * F], [-0.85 / q, -0.85, 1.15 * F]
    opt = BoxSR3(0.05, 1.0, lower=lo, upper=hi, normalize_columns=True).fit(Theta, y)
    true = np.zeros(len(names))
    true[[0, 1, 2, 6]] = [-1 / q, -1.0, F, -0.3]
    np.testing.assert_array_equal(opt.coef_[0] != 0, true != 0)
    # dominant terms within 1 %; the small damping term (-1/Q) is noise-limited: within 5 %
    np.testing.assert_allclose(opt.coef_[0][[1, 2, 6]], true[[1, 2, 6]], rtol=0.01)
    assert opt.coef_[0, 0] == pytest.approx(-1 / q, rel=0.05)


def test_path_gram_equals_fit_and_sample_weight_equals_duplication():
    X, y, _ = _sparse_problem(seed=9)
    lo = np.full(X.shape[1], -1.5)
    opt = BoxSR3(0.3, 0.2, lower=lo, thresholds=np.r_[0.3 * np.ones(7), 0.0],
                 normalize_columns=True)
    G, b = X.T @ X, X.T @ y
    ts = np.array([0.1, 0.3, 0.9])
    path, n_iter = opt.path_gram(G, b, ts)
    for k, t in enumerate(ts):
        single = BoxSR3(t, 0.2, lower=lo, thresholds=np.r_[t * np.ones(7), 0.0],
                        normalize_columns=True).fit(X, y)
        np.testing.assert_allclose(path[k], single.coef_, atol=1e-12)
        assert n_iter[k] == single.n_iter_
    w = np.random.default_rng(0).integers(0, 3, size=X.shape[0])
    a = BoxSR3(0.3, 0.2).fit(X, y, sample_weight=w)
    b2 = BoxSR3(0.3, 0.2).fit(np.repeat(X, w, axis=0), np.repeat(y, w))
    np.testing.assert_allclose(a.coef_, b2.coef_, atol=1e-10)


@pytest.mark.parametrize(("kwargs", "match"), [
    (dict(threshold=-0.1), "threshold"),
    (dict(nu=0.0), "nu"),
    (dict(nu=-1.0), "nu"),
    (dict(tol=0.0), "tol"),
    (dict(max_iter=0), "max_iter"),
    (dict(lower=[0.0, 1.0, 0, 0], upper=[1.0, 0.5, 1, 1]), "lower must be <= upper"),
    (dict(lower=np.zeros(3)), "lower must have shape"),
    (dict(thresholds=np.ones((2, 4))), "thresholds must have shape"),
    (dict(thresholds=-np.ones(4)), "thresholds"),
    (dict(constraint_lhs=np.ones((1, 3)), constraint_rhs=[1.0]), "constraint_lhs"),
    (dict(constraint_lhs=np.ones((1, 4))), "together"),
    (dict(constraint_lhs=np.ones((1, 4)), constraint_rhs=[1.0], constraint_order="x"),
     "constraint_order"),
    (dict(constraint_lhs=np.ones((2, 4)), constraint_rhs=[1.0, 2.0]), "full row rank"),
])
def test_bad_settings_raise(kwargs, match):
    X = np.random.default_rng(0).normal(size=(30, 4))
    y = X[:, 0]
    with pytest.raises(ValueError, match=match):
        BoxSR3(**kwargs).fit(X, y)


def test_bad_data_raise():
    with pytest.raises(ValueError, match="y must have shape"):
        BoxSR3().fit(np.ones((10, 2)), np.ones(9))
    with pytest.raises(ValueError, match="G must be square"):
        BoxSR3().fit_gram(np.ones((2, 3)), np.ones(2))


def test_constrained_lstsq_ill_conditioned_terminates_at_optimum():
    """Monomial columns (cond ~ 1e8): the active set must not cycle on round-off steps."""
    s = np.linspace(0.05, 1.0, 400)
    X = np.column_stack([s**k for k in range(8)])
    y = np.sin(3 * s) + 0.01 * np.random.default_rng(10).normal(size=s.size)
    lo = np.full(8, -np.inf)
    hi = np.full(8, np.inf)
    lo[1], hi[1] = 3.1, 3.5  # the slope near 0 is ~3: this bound is active
    hi[3] = -5.0
    x = constrained_lstsq(X.T @ X, X.T @ y, lower=lo, upper=hi, max_iter=30)
    ref = _cvx_lstsq(X, y, np.ones(8, bool), lo, hi)
    assert np.all(x >= lo) and np.all(x <= hi)
    assert np.sum((X @ x - y) ** 2) <= np.sum((X @ ref - y) ** 2) * (1 + 1e-6)
