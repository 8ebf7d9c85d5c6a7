"""PSS/E governors IEESGO and WSIEG1 (src/jaxdse/_models/governors.py).

The reference each module is compared with is written here from the PSS/E Model Library
block diagram, in plain Python floats (one block after another, limits and deadbands as
if-statements, the valve characteristic by ``numpy.interp`` with its end segments extended)
and integrated by ``scipy.integrate.solve_ivp`` at tight tolerances. The module runs through
a jitted RK4 (one compile per class; the parameters are traced leaves).
"""

from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from jaxdse._models.governors import GOVERNORS, IEESGO, WSIEG1

ACTIVSG_DYR = Path(__file__).resolve().parents[3] / "shared/data/activsg2000/ACTIVSg2000_dynamics.dyr"
T_M0 = 0.7
DT = 2e-3

# IEEE 1973 report style data; K1 = 1/droop on the machine base
IEESGO_DATA = dict(t1_s=0.2, t2_s=0.05, t3_s=0.15, t4_s=0.3, t5_s=5.0, t6_s=0.5, k1=20.0,
                   k2=0.7, k3=0.4, p_max_pu=0.9, p_min_pu=0.0)
# WECC style: deadband, backlash and a nonlinear valve characteristic
WSIEG1_DATA = dict(k=20.0, t1_s=0.5, t2_s=0.1, t3_s=0.12, uo_pu_s=0.2, uc_pu_s=-0.3,
                   p_max_pu=1.0, p_min_pu=0.0, t4_s=0.25, k1=0.3, k2=0.0, t5_s=6.0, k3=0.3,
                   k4=0.0, t6_s=0.5, k5=0.4, k6=0.0, t7_s=0.0, k7=0.0, k8=0.0, db1_pu=0.0006,
                   err_pu=0.0, db2_pu=0.002, gv1_pu=0.0, pgv1_pu=0.0, gv2_pu=0.3, pgv2_pu=0.4,
                   gv3_pu=0.6, pgv3_pu=0.7, gv4_pu=0.8, pgv4_pu=0.85, gv5_pu=1.0, pgv5_pu=0.95,
                   iblock=0.0)


# --- the module: RK4 (one compile per class) ---------------------------------------------------

@eqx.filter_jit
def _rk4(gov, x0, dw0, dw_rate, t_ref, n, dt):
    def f(x, t):
        return gov.vector_field(x, dw0 + dw_rate * t, t_ref)

    def body(carry, _):
        x, t = carry
        k1 = f(x, t)
        k2 = f(x + 0.5 * dt * k1, t + 0.5 * dt)
        k3 = f(x + 0.5 * dt * k2, t + 0.5 * dt)
        k4 = f(x + dt * k3, t + dt)
        x = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        return (x, t + dt), (gov.torque(x, dw0 + dw_rate * (t + dt)), x)

    _, (tm, xs) = jax.lax.scan(body, (x0, jnp.zeros(())), None, length=n)
    return tm, xs


@eqx.filter_jit
def _rest(gov, t_m, dw):
    t_ref = gov.reference_from_steady(t_m, dw)
    x0 = gov.steady_state(t_ref, dw)
    return t_ref, x0, gov.vector_field(x0, dw, t_ref), gov.torque(x0, dw)


def simulate(gov, dw_step=0.0, dw_rate=0.0, ref_step=0.0, t_end=20.0, dt=DT):
    """From rest at Tm = T_M0, dw = 0: dw(t) = dw_step + dw_rate t, reference + ref_step."""
    t_ref, x0, _, _ = _rest(gov, T_M0, 0.0)
    n = int(round(t_end / dt))
    tm, xs = _rk4(gov, x0, jnp.asarray(dw_step, float), jnp.asarray(dw_rate, float),
                  t_ref + ref_step, n, jnp.asarray(dt, float))
    return np.asarray(tm), np.asarray(xs), float(t_ref), np.asarray(x0)


# --- references from the block diagrams --------------------------------------------------------

def _lag(u, x, t):
    return (x, (u - x) / t) if t > 0 else (u, 0.0)


def _clip(v, lo, hi):
    return min(max(v, lo), hi)


def ieesgo_reference(p, dw_of, p0):
    """(deriv, Tm) of IEESGO; states [T1 lead-lag, T3 lag, T4, T5, T6]."""

    def parts(t, x):
        dw = dw_of(t)
        if p["t1_s"] > 0:
            g = p["k1"] * (x[0] + p["t2_s"] / p["t1_s"] * (dw - x[0]))
            d0 = (dw - x[0]) / p["t1_s"]
        else:
            g, d0 = p["k1"] * dw, 0.0
        g, d1 = _lag(g, x[1], p["t3_s"])
        pin = _clip(p0 - g, p["p_min_pu"], p["p_max_pu"])
        hp, d2 = _lag(pin, x[2], p["t4_s"])
        ip, d3 = _lag(p["k2"] * hp, x[3], p["t5_s"])
        lp, d4 = _lag(p["k3"] * ip, x[4], p["t6_s"])
        tm = (1 - p["k2"]) * hp + (1 - p["k3"]) * ip + lp
        return [d0, d1, d2, d3, d4], tm

    x0 = [0.0, 0.0, T_M0, p["k2"] * T_M0, p["k2"] * p["k3"] * T_M0]   # at rest, dw = 0
    return (lambda t, x: parts(t, x)[0]), (lambda t, x: parts(t, x)[1]), x0


def wsieg1_reference(p, dw_of, po):
    """(deriv, Tm, x0) of WSIEG1; states [LL, GV, GV after backlash, x4..x7]."""
    gv_pts = np.array([p[f"gv{k}_pu"] for k in range(1, 6)])
    pgv_pts = np.array([p[f"pgv{k}_pu"] for k in range(1, 6)])
    table = bool(np.any(gv_pts != 0) or np.any(pgv_pts != 0))

    def valve(g):
        if not table:
            return g
        if g < gv_pts[0]:
            return pgv_pts[0] + (g - gv_pts[0]) * (pgv_pts[1] - pgv_pts[0]) / (gv_pts[1] - gv_pts[0])
        if g > gv_pts[-1]:
            return pgv_pts[-1] + (g - gv_pts[-1]) * (pgv_pts[-1] - pgv_pts[-2]) / (gv_pts[-1] - gv_pts[-2])
        return float(np.interp(g, gv_pts, pgv_pts))

    lo, hi = p["p_min_pu"], p["p_max_pu"]
    if p["iblock"] in (1, 3) and lo == 0:
        lo = po
    if p["iblock"] in (2, 3) and hi == 0:
        hi = po

    def parts(t, x):
        dw = dw_of(t)
        db = p["db1_pu"]
        e = dw - db if dw > db else (dw + db if dw < -db else 0.0)
        if p["t1_s"] > 0:
            ll = p["k"] * (x[0] + p["t2_s"] / p["t1_s"] * (e - x[0]))
            d0 = (e - x[0]) / p["t1_s"]
        else:
            ll, d0 = p["k"] * e, 0.0
        gvb = x[2] if p["db2_pu"] > 0 else x[1]
        rate = _clip((po - ll - gvb) / p["t3_s"], p["uc_pu_s"], p["uo_pu_s"])
        if (x[1] >= hi and rate > 0) or (x[1] <= lo and rate < 0):
            rate = 0.0
        gap = x[1] - x[2]
        if p["db2_pu"] <= 0 or (gap >= p["db2_pu"] and rate > 0) or (gap <= -p["db2_pu"] and rate < 0):
            d2 = rate
        else:
            d2 = 0.0
        y = valve(gvb)
        outs, ds = [], []
        for k, tk in zip(range(3, 7), ("t4_s", "t5_s", "t6_s", "t7_s")):
            y, d = _lag(y, x[k], p[tk])
            outs.append(y)
            ds.append(d)
        tm = p["k1"] * outs[0] + p["k3"] * outs[1] + p["k5"] * outs[2] + p["k7"] * outs[3]
        return [d0, rate, d2] + ds, tm

    return (lambda t, x: parts(t, x)[0]), (lambda t, x: parts(t, x)[1])


def run_reference(deriv, tm_of, x0, t_end, dt=DT):
    t_eval = dt * np.arange(1, int(round(t_end / dt)) + 1)
    sol = solve_ivp(deriv, (0.0, t_end), list(x0), t_eval=t_eval, method="RK45", rtol=1e-10,
                    atol=1e-12, max_step=0.02)
    assert sol.success
    return np.array([tm_of(t, sol.y[:, k]) for k, t in enumerate(t_eval)])


def _p(gov):
    return {f: float(getattr(gov, f)) for f in gov.__dataclass_fields__}


# --- (1) steady state and flat runs -----------------------------------------------------------

_tc = st.one_of(st.just(0.0), st.floats(0.05, 8.0))


@st.composite
def governors(draw, cls):
    if cls is IEESGO:
        return IEESGO(t1_s=draw(_tc), t2_s=draw(_tc), t3_s=draw(_tc), t4_s=draw(st.floats(0.05, 1)),
                      t5_s=draw(_tc), t6_s=draw(_tc), k1=draw(st.floats(5, 50)),
                      k2=draw(st.floats(0, 1)), k3=draw(st.floats(0, 1)),
                      p_max_pu=draw(st.floats(0.8, 1.2)), p_min_pu=draw(st.floats(0, 0.3)))
    # a valve characteristic from (0, 0) to about (1, 1): the operating point is reachable
    gv = np.concatenate([[0.0], np.cumsum(draw(st.lists(st.floats(0.1, 0.4), min_size=4,
                                                        max_size=4)))])
    pgv = np.concatenate([[0.0], np.cumsum(draw(st.lists(st.floats(0.05, 0.4), min_size=4,
                                                         max_size=4)))])
    gv, pgv = gv / gv[-1] * draw(st.floats(1.0, 1.2)), pgv / pgv[-1] * draw(st.floats(1.0, 1.1))
    table = draw(st.booleans())
    pts = {}
    for k in range(5):
        pts[f"gv{k + 1}_pu"] = float(gv[k]) if table else 0.0
        pts[f"pgv{k + 1}_pu"] = float(pgv[k]) if table else 0.0
    return WSIEG1(k=draw(st.floats(5, 50)), t1_s=draw(_tc), t2_s=draw(_tc),
                  t3_s=draw(st.floats(0.05, 0.5)), uo_pu_s=draw(st.floats(0.05, 1)),
                  uc_pu_s=-draw(st.floats(0.05, 1)), p_max_pu=draw(st.floats(1.5, 2.0)),
                  p_min_pu=0.0, t4_s=draw(_tc), k1=draw(st.floats(0.2, 0.5)), t5_s=draw(_tc),
                  k3=draw(st.floats(0.2, 0.4)), t6_s=draw(_tc), k5=draw(st.floats(0.2, 0.3)),
                  t7_s=draw(_tc), k7=draw(st.floats(0, 0.3)), db1_pu=draw(st.floats(0, 0.001)),
                  db2_pu=draw(st.floats(0, 0.01)), iblock=draw(st.sampled_from([0, 1, 2, 3])),
                  **pts)


@pytest.mark.slow
@pytest.mark.parametrize("cls", [IEESGO, WSIEG1])
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_steady_state_holds_and_a_flat_run_stays_flat(cls, data):
    gov = data.draw(governors(cls))
    t_m = data.draw(st.floats(0.3, 0.6))
    t_ref, x0, f0, tm0 = _rest(gov, t_m, 0.0)
    assert abs(float(tm0) - t_m) < 1e-12
    assert float(jnp.max(jnp.abs(f0))) < 1e-9
    tm, xs = _rk4(gov, x0, jnp.zeros(()), jnp.zeros(()), t_ref, 2000, jnp.asarray(0.01))
    assert np.max(np.abs(np.asarray(xs) - np.asarray(x0)[None, :])) < 1e-6
    assert np.max(np.abs(np.asarray(tm) - t_m)) < 1e-6


def test_speed_off_nominal_steady_state():
    for gov in (IEESGO(**IEESGO_DATA), WSIEG1(**WSIEG1_DATA)):
        _, x0, f0, tm0 = _rest(gov, 0.6, -0.002)
        assert float(jnp.max(jnp.abs(f0))) < 1e-12 and abs(float(tm0) - 0.6) < 1e-12


# --- (2) against the block diagram ----------------------------------------------------------

SCENARIOS = {
    "speed step": dict(dw_step=-0.003),
    "speed ramp": dict(dw_rate=-0.0004),
    "reference step": dict(ref_step=0.05),
    "speed rise into PMIN": dict(dw_step=0.05),
}
MAX_DIFF = {}


@pytest.mark.parametrize("cls,data", [(IEESGO, IEESGO_DATA), (WSIEG1, WSIEG1_DATA)],
                         ids=["IEESGO", "WSIEG1"])
@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_matches_block_diagram_reference(cls, data, scenario):
    gov = cls(**data)
    kw = SCENARIOS[scenario]
    t_end = 15.0
    tm, _, t_ref, x0 = simulate(gov, t_end=t_end, **kw)
    p = _p(gov)

    def dw_of(t):
        return kw.get("dw_step", 0.0) + kw.get("dw_rate", 0.0) * t

    po = t_ref + kw.get("ref_step", 0.0)
    if cls is IEESGO:
        deriv, tm_of, x0 = ieesgo_reference(p, dw_of, po)
    else:
        deriv, tm_of = wsieg1_reference(p, dw_of, po)
    tm_ref = run_reference(deriv, tm_of, x0, t_end)
    scale = np.max(np.abs(tm_ref - T_M0))
    assert scale > 1e-3
    diff = np.max(np.abs(tm - tm_ref))
    MAX_DIFF[(cls.__name__, scenario)] = diff
    print(f"{cls.__name__} {scenario}: max |Tm - reference| = {diff:.2e} pu (swing {scale:.3f})")
    assert diff < 1e-3 * scale      # RK4 at 2 ms across the kinks of the limits and deadbands


# --- (3) blocks that reduce to lags: closed form ------------------------------------------------

def _two_lags(t, ta, tb):
    """Unit step response of 1/((1 + s ta)(1 + s tb))."""
    return 1.0 - (ta * np.exp(-t / ta) - tb * np.exp(-t / tb)) / (ta - tb)


def test_linear_paths_match_closed_form():
    dw = -0.002
    t = DT * np.arange(1, int(round(5.0 / DT)) + 1)
    # IEESGO, T1 = 0 and K2 = 0: Tm = P0 - K1 dw / ((1 + s T3)(1 + s T4))
    g = IEESGO(t1_s=0.0, t2_s=0.0, t3_s=0.4, t4_s=0.25, t5_s=5.0, t6_s=0.5, k1=20.0, k2=0.0,
               k3=0.5, p_max_pu=2.0, p_min_pu=0.0)
    tm, _, _, _ = simulate(g, dw_step=dw, t_end=5.0)
    closed = T_M0 - 20.0 * dw * _two_lags(t, 0.4, 0.25)
    assert np.max(np.abs(tm - closed)) < 1e-9
    # WSIEG1 without rate limits, deadbands or table, K1 = 1: the valve loop is a lag T3
    w = WSIEG1(k=20.0, t1_s=0.0, t2_s=0.0, t3_s=0.1, uo_pu_s=10.0, uc_pu_s=-10.0, p_max_pu=2.0,
               p_min_pu=0.0, t4_s=0.3, k1=1.0, t5_s=0.0, k3=0.0, t6_s=0.0, k5=0.0, t7_s=0.0)
    tm, _, _, _ = simulate(w, dw_step=dw, t_end=5.0)
    closed = T_M0 - 20.0 * dw * _two_lags(t, 0.1, 0.3)
    assert np.max(np.abs(tm - closed)) < 1e-9


# --- (4) limits, deadbands, blocking -----------------------------------------------------------

def test_ieesgo_power_limits():
    g = IEESGO(**IEESGO_DATA)
    tm, _, _, _ = simulate(g, dw_step=-0.05, t_end=60.0, dt=0.01)
    assert np.max(tm) <= IEESGO_DATA["p_max_pu"] + 1e-12
    assert tm[-1] == pytest.approx(IEESGO_DATA["p_max_pu"], abs=1e-4)
    tm, _, _, _ = simulate(g, dw_step=0.05, t_end=30.0)
    assert np.min(tm) >= IEESGO_DATA["p_min_pu"] - 1e-12


def test_wsieg1_rate_and_position_limits_and_blocking():
    w = WSIEG1(**WSIEG1_DATA)
    _, xs, _, x0 = simulate(w, dw_step=-0.05, t_end=10.0)
    gv = xs[:, 1]
    assert np.max(np.diff(gv)) / DT <= WSIEG1_DATA["uo_pu_s"] + 1e-9
    # the integrator may cross PMAX within its last step (non-windup), by at most Uo DT
    assert np.max(gv) <= WSIEG1_DATA["p_max_pu"] + WSIEG1_DATA["uo_pu_s"] * DT
    assert np.max(np.diff(gv[-100:])) == 0.0
    _, xs, _, _ = simulate(w, dw_step=0.05, t_end=10.0)
    assert np.min(np.diff(xs[:, 1])) / DT >= WSIEG1_DATA["uc_pu_s"] - 1e-9
    # IBLOCK 2 with PMAX = 0: the governor cannot raise the valve; lowering still works
    blk = WSIEG1(**dict(WSIEG1_DATA, iblock=2, p_max_pu=0.0))
    _, xs, _, x0 = simulate(blk, dw_step=-0.01, t_end=5.0)
    assert np.max(np.abs(xs[:, 1] - x0[1])) < 1e-12
    _, xs, _, x0 = simulate(blk, dw_step=0.01, t_end=5.0)
    assert xs[-1, 1] < x0[1] - 0.05
    blk1 = WSIEG1(**dict(WSIEG1_DATA, iblock=1))
    _, xs, _, x0 = simulate(blk1, dw_step=0.01, t_end=5.0)
    assert np.max(np.abs(xs[:, 1] - x0[1])) < 1e-12


def test_wsieg1_deadbands():
    w = WSIEG1(**WSIEG1_DATA)
    tm, xs, _, x0 = simulate(w, dw_step=0.0005, t_end=5.0)        # inside DB1 = 0.0006
    assert np.max(np.abs(tm - T_M0)) < 1e-12
    # backlash DB2 = 0.004 (half-width) with the feedback taken after it: a speed step asking
    # for +0.002 of valve moves GV through the band first (GVb still), then GVb by 0.002 and
    # GV by 0.002 + DB2
    small = WSIEG1(**dict(WSIEG1_DATA, db2_pu=0.004))
    tm, xs, _, x0 = simulate(small, dw_step=-0.0007, t_end=10.0)  # K (0.0007 - 0.0006) = 0.002
    gv, gvb = xs[:, 1] - x0[1], xs[:, 2] - x0[2]
    assert np.all(gvb[gv < 0.004 - 1e-9] == 0.0)                 # GVb held inside the band
    assert abs(gvb[-1] - 0.002) < 1e-6 and abs(gv[-1] - 0.006) < 1e-6
    assert np.all(np.abs(gv - gvb) <= 0.004 + 1e-4)    # a discrete step may overshoot the edge


# --- (5) zero time constants --------------------------------------------------------------------

@pytest.mark.parametrize("gov", [
    IEESGO(t1_s=0.0, t2_s=0.0, t3_s=0.0, t4_s=0.3, t5_s=0.0, t6_s=0.0, k1=20.0, k2=0.5, k3=0.5),
    WSIEG1(**dict(WSIEG1_DATA, t1_s=0.0, t2_s=0.0, t4_s=0.0, t5_s=0.0, t6_s=0.0, t7_s=0.0,
                  db1_pu=0.0, db2_pu=0.0)),
], ids=["IEESGO", "WSIEG1"])
def test_zero_time_constants_give_finite_values_and_gradients(gov):
    def loss(g):
        t_ref = g.reference_from_steady(0.7, 0.0)
        x0 = g.steady_state(t_ref, 0.0)
        x1 = x0 + 0.01 * g.vector_field(x0, -0.002, t_ref)
        return g.torque(x1, -0.002) + jnp.sum(g.vector_field(x1, -0.002, t_ref))

    assert np.isfinite(float(eqx.filter_jit(loss)(gov)))
    grads = jax.tree_util.tree_leaves(eqx.filter_jit(eqx.filter_grad(loss))(gov))
    assert all(np.all(np.isfinite(np.asarray(v))) for v in grads)


def test_ieesgo_needs_t4_and_ordered_limits():
    with pytest.raises(ValueError, match="t4_s must be > 0"):
        IEESGO(**dict(IEESGO_DATA, t4_s=0.0))
    with pytest.raises(ValueError, match="PMAX"):
        IEESGO(**dict(IEESGO_DATA, p_max_pu=-0.1))


# --- (6) records --------------------------------------------------------------------------------

IEESGO_CONS = (0.2, 0.05, 0.15, 0.3, 5.0, 0.5, 20.0, 0.7, 0.4, 0.9, 0.0)
WSIEG1_CONS = (0, 0, 20.0, 0.5, 0.1, 0.12, 0.2, -0.3, 1.0, 0.0, 0.25, 0.3, 0.0, 6.0, 0.3, 0.0,
               0.5, 0.4, 0.0, 0.0, 0.0, 0.0, 0.0006, 0.0, 0.002, 0.0, 0.0, 0.3, 0.4, 0.6, 0.7,
               0.8, 0.85, 1.0, 0.95, 0)


def _read(tmp_path, text):
    from jaxdse._io.psse import read_dyr

    path = tmp_path / "case.dyr"
    path.write_text(text)
    return read_dyr(str(path))


def _rec(model, cons):
    return f"1 '{model}' 1 " + " ".join(f"{c:g}" for c in cons) + " /\n"


def test_records_in_con_order(tmp_path):
    from jaxdse._io.psse import GOVERNOR_FIELDS, governor_from_dyr

    if "IEESGO" not in GOVERNOR_FIELDS:
        pytest.skip("the .dyr reader's governor tables do not have IEESGO/WSIEG1 yet")
    dyr = _read(tmp_path, _rec("IEESGO", IEESGO_CONS) + _rec("WSIEG1", WSIEG1_CONS).replace(
        "1 'WSIEG1' 1", "2 'WSIEG1' 1"))
    g = governor_from_dyr(dyr.records[0])
    assert isinstance(g, IEESGO)
    assert [float(getattr(g, f)) for f in ("t1_s", "t2_s", "t3_s", "t4_s", "t5_s", "t6_s", "k1",
                                           "k2", "k3", "p_max_pu", "p_min_pu")] == list(IEESGO_CONS)
    w = governor_from_dyr(dyr.records[1])
    assert isinstance(w, WSIEG1)
    names = ("k", "t1_s", "t2_s", "t3_s", "uo_pu_s", "uc_pu_s", "p_max_pu", "p_min_pu", "t4_s",
             "k1", "k2", "t5_s", "k3", "k4", "t6_s", "k5", "k6", "t7_s", "k7", "k8", "db1_pu",
             "err_pu", "db2_pu") + tuple(f"{a}{k}_pu" for k in range(1, 6) for a in ("gv", "pgv")) \
        + ("iblock",)
    assert [float(getattr(w, f)) for f in names] == [float(c) for c in WSIEG1_CONS[2:]]
    assert GOVERNORS["IEESGO"] is IEESGO and GOVERNORS["WSIEG1"] is WSIEG1
    assert len(GOVERNOR_FIELDS["IEESGO"]) == 11 and len(GOVERNOR_FIELDS["WSIEG1"]) == 36


BAD = [
    ("IEESGO", IEESGO_CONS[:-1], "10 constants, expected 11"),
    ("WSIEG1", WSIEG1_CONS + (0,), "37 constants, expected 36"),
    ("IEESGO", IEESGO_CONS[:3] + (0.0,) + IEESGO_CONS[4:], "IEESGO bus .*: T4 must be > 0"),
    ("IEESGO", IEESGO_CONS[:9] + (0.0, 0.5), "PMAX"),
    ("WSIEG1", WSIEG1_CONS[:-1] + (5,), "IBLOCK must be 0, 1, 2 or 3"),
    ("WSIEG1", WSIEG1_CONS[:27] + (0.9,) + WSIEG1_CONS[28:], "GV1 < GV2"),
    ("WSIEG1", WSIEG1_CONS[:7] + (0.1,) + WSIEG1_CONS[8:], "Uc must be < 0"),
]


@pytest.mark.parametrize("model,cons,message", BAD, ids=[b[2] for b in BAD])
def test_bad_records_are_refused_in_one_line(tmp_path, model, cons, message):
    from jaxdse._io.psse import GOVERNOR_FIELDS, governor_from_dyr

    if model not in GOVERNOR_FIELDS:
        pytest.skip("the .dyr reader's governor tables do not have IEESGO/WSIEG1 yet")
    with pytest.raises(ValueError, match=message) as e:
        governor_from_dyr(_read(tmp_path, _rec(model, cons)).records[0])
    assert "\n" not in str(e.value)


def test_real_records_of_activsg2000():
    if not ACTIVSG_DYR.exists():
        pytest.skip(f"{ACTIVSG_DYR} not present")
    from jaxdse._io.psse import governor_from_dyr, read_dyr

    recs = [r for r in read_dyr(str(ACTIVSG_DYR)).records if r.model in ("IEESGO", "WSIEG1")]
    if not recs:
        pytest.skip("ACTIVSg2000 has no IEESGO/WSIEG1 record (its governors: GGOV1, IEEEG1, HYGOV)")
    for r in recs:
        g = governor_from_dyr(r)
        _, _, f0, _ = _rest(g, 0.6, 0.0)
        assert float(jnp.max(jnp.abs(f0))) < 1e-12
