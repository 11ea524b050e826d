"""Implicit Euler is first order on the breathing scene's metrics: the errors of their
time series (rib lift, apex descent, pressure) against a fine symplectic Euler reference."""

from hybrid.resolve import resolve_scene
from hybrid.studies.work_precision import H0_IMPLICIT, _errors, observed_order, simulate

KEYS = ("rib_lift_error_mm", "apex_descent_error_mm", "pressure_error")


def test_implicit_euler_first_order_on_breathing_series():
    scene = resolve_scene("breathing", overrides=["mesh.level=2"])  # 318 points
    window = 0.3
    ref = simulate("breathing", "symplectic_euler", 6, window, coupled=scene)  # 15.6 us
    check = simulate("breathing", "symplectic_euler", 5, window, coupled=scene)
    ks = (1, 2, 3)  # 5, 2.5, 1.25 ms
    errs = [_errors(simulate("breathing", "implicit_euler", k, window, coupled=scene, h0=H0_IMPLICIT), ref) for k in ks]
    est = _errors(check, ref)  # the reference's own error, by Richardson (first order)
    dts = [H0_IMPLICIT / 2**k for k in ks]
    for key in KEYS:
        e = [r[key] for r in errs]
        assert est[key] < 0.05 * e[-1], (key, est[key], e)
        assert all(a > b for a, b in zip(e, e[1:])), (key, e)
        p = observed_order(dts, e)
        assert 0.9 <= p <= 1.1, (key, p, e)
