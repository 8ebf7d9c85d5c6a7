"""PSS/E dual-input stabilisers PSS2A and PSS2B (src/jaxdse/_models/stabilisers.py).

The reference the modules are compared with is written here from the block diagram of the
PSS/E Model Library / IEEE Std 421.5 (PSS2A, PSS2B): each block's transfer function becomes a
state-space model (``scipy.signal.tf2ss``), the blocks are connected in series and parallel
as the diagram draws them (one linear system from each input to the output), and the system
is integrated by ``scipy.integrate.solve_ivp`` at tight tolerances; the input limits (PSS2B)
act on the inputs and the output limit on the output, both static.
"""

import math
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.signal import tf2ss

from jaxdse._models.base import StabiliserInputs
from jaxdse._models.stabilisers import (
    PSS2A,
    PSS2B,
    RTF_MAX_STAGES,
    STABILISER_FIELDS,
    STABILISERS,
    stabiliser_from_dyr,
)

ACTIVSG_DYR = Path(__file__).resolve().parents[3] / "shared/data/activsg2000/ACTIVSg2000_dynamics.dyr"

# IEEE Std 421.5 sample data style (speed + electrical power, integral of accelerating power)
PSS2A_DATA = dict(m_rtf=5, n_rtf=1, tw1_s=2.0, tw2_s=2.0, t6_s=0.0, tw3_s=2.0, tw4_s=0.0,
                  t7_s=2.0, ks2=0.3, ks3=1.0, t8_s=0.5, t9_s=0.1, ks1=10.0, t1_s=0.15, t2_s=0.03,
                  t3_s=0.2, t4_s=0.04, vst_max_pu=0.1, vst_min_pu=-0.1)
PSS2B_DATA = dict(PSS2A_DATA, t10_s=0.1, t11_s=0.05, vs1_max_pu=0.02, vs1_min_pu=-0.02,
                  vs2_max_pu=1.25, vs2_min_pu=-1.25)
# with a 2nd washout on input 2, T6 > 0 and a 2x2 ramp-tracking filter
PSS2A_FULL = dict(PSS2A_DATA, m_rtf=2, n_rtf=2, t6_s=0.02, tw4_s=3.0, ks3=0.8)

DT = 1e-3


def inputs(speed=0.0, pe=0.8, vt=1.0):
    z = jnp.zeros(())
    return StabiliserInputs(jnp.asarray(speed, float), z, jnp.asarray(pe, float), z,
                            jnp.asarray(vt, float), z)


# --- the module, integrated by RK4 (one compile per class) ------------------------------------

@eqx.filter_jit
def _simulate(m, x0, u0, step, rate, n, dt=DT):
    """VST at t = dt, 2 dt, ... for inputs u(t) = u0 + step + rate t (speed, PELEC), RK4."""
    DT = dt  # noqa: N806

    def inp(t):
        u = u0 + step + rate * t
        return inputs(u[0], u[1])

    def f(x, t):
        return m.vector_field(x, inp(t))

    def body(carry, k):
        x, t = carry
        k1 = f(x, t)
        k2 = f(x + 0.5 * DT * k1, t + 0.5 * DT)
        k3 = f(x + 0.5 * DT * k2, t + 0.5 * DT)
        k4 = f(x + DT * k3, t + DT)
        x = x + DT / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        return (x, t + DT), (m.output(x, inp(t + DT)), x)

    _, (y, xs) = jax.lax.scan(body, (x0, jnp.zeros(())), jnp.arange(n))
    return y, xs


@eqx.filter_jit
def _rest(m, u0):
    """(rest state at constant inputs u0, its vector field)."""
    x0 = m.initial_state(inputs(u0[0], u0[1]))
    return x0, m.vector_field(x0, inputs(u0[0], u0[1]))


def simulate(m, u0, step=(0.0, 0.0), rate=(0.0, 0.0), t_end=10.0, dt=DT):
    u0 = jnp.asarray(u0, float)
    x0, _ = _rest(m, u0)
    n = int(round(t_end / dt))
    y, xs = _simulate(m, x0, u0, jnp.asarray(step, float), jnp.asarray(rate, float), n,
                      jnp.asarray(dt, float))
    return np.asarray(y), np.asarray(xs), np.asarray(x0)


# --- the reference, from the block diagram ----------------------------------------------------

def _block(num, den):
    """State space of one first-order block num/den (polynomials in s, as the diagram draws it)."""
    if len(den) == 1:
        return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[num[-1] / den[0]]])
    return tf2ss(num, den)


def _series(*systems):
    """The blocks one after the other (the first gets the input)."""
    a, b, c, d = systems[0]
    for a2, b2, c2, d2 in systems[1:]:
        n1, n2 = a.shape[0], a2.shape[0]
        a = np.block([[a, np.zeros((n1, n2))], [b2 @ c, a2]])
        b = np.vstack([b, b2 @ d])
        c = np.hstack([d2 @ c, c2])
        d = d2 @ d
    return a, b, c, d


def _parallel(s1, s2, k1, k2):
    """k1 s1 + k2 s2 (same input)."""
    (a1, b1, c1, d1), (a2, b2, c2, d2) = s1, s2
    n1, n2 = a1.shape[0], a2.shape[0]
    a = np.block([[a1, np.zeros((n1, n2))], [np.zeros((n2, n1)), a2]])
    return a, np.vstack([b1, b2]), np.hstack([k1 * c1, k2 * c2]), k1 * d1 + k2 * d2


def _gain(k):
    return _block([k], [1.0])


def _lag(t, k=1.0):          # k/(1 + sT); T = 0: the gain
    return _block([k], [t, 1.0]) if t > 0 else _gain(k)


def _lead_lag(ta, tb):       # (1 + s Ta)/(1 + s Tb); Tb = 0: bypassed
    return _block([ta, 1.0], [tb, 1.0]) if tb > 0 else _gain(1.0)


def _washout(t):             # sT/(1 + sT); T = 0: bypassed
    return _block([t, 0.0], [t, 1.0]) if t > 0 else _gain(1.0)


def reference_systems(p):
    """(G1, G2): VST/u1 and VST/u2 before the output limit, as state-space models built block
    by block from the diagram."""
    m, n = int(p["m_rtf"]), int(p["n_rtf"])
    if m > 0 and n > 0 and p["t9_s"] > 0:
        section = [_lead_lag(p["t8_s"], p["t9_s"])] + [_lag(p["t9_s"])] * (m - 1)
        rtf = _series(*(section * n))
    else:
        rtf = _gain(1.0)
    lls = [_lead_lag(p["t1_s"], p["t2_s"]), _lead_lag(p["t3_s"], p["t4_s"])]
    if "t10_s" in p:
        lls.append(_lead_lag(p["t10_s"], p["t11_s"]))
    g1 = _series(_washout(p["tw1_s"]), _washout(p["tw2_s"]), _lag(p["t6_s"]), rtf,
                 _gain(p["ks1"]), *lls)
    g2 = _series(_washout(p["tw3_s"]), _washout(p["tw4_s"]), _lag(p["t7_s"], p["ks2"]),
                 _parallel(rtf, _gain(1.0), p["ks3"], -1.0), _gain(p["ks1"]), *lls)
    return g1, g2


def reference_response(p, u0, step, rate, t_end, limits_in=None):
    """VST(t) at t = DT, 2 DT, ... by solve_ivp on the block-by-block state-space models."""
    t_eval = DT * np.arange(1, int(round(t_end / DT)) + 1)

    def u_of(t, k):
        u = u0[k] + step[k] + rate[k] * t
        if limits_in is not None:
            u = min(max(u, limits_in[k][0]), limits_in[k][1])
        return u

    u_init = [u0[k] if limits_in is None else min(max(u0[k], limits_in[k][0]), limits_in[k][1])
              for k in range(2)]
    y = np.zeros_like(t_eval)
    for k, (a, b, c, d) in enumerate(reference_systems(p)):
        u_t = np.array([u_of(t, k) for t in t_eval])
        if a.size == 0:
            y += d[0, 0] * u_t
            continue
        x0 = -np.linalg.solve(a, b[:, 0]) * u_init[k]
        sol = solve_ivp(lambda t, x: a @ x + b[:, 0] * u_of(t, k), (0.0, t_end), x0,
                        t_eval=t_eval, rtol=1e-11, atol=1e-13, method="LSODA", max_step=0.05)
        y += (c @ sol.y)[0] + d[0, 0] * u_t
    return np.clip(y, p["vst_min_pu"], p["vst_max_pu"])


def _params(m):
    return {f: float(getattr(m, f)) for f in m.__dataclass_fields__ if f.endswith(("_s", "_pu"))
            or f.startswith(("ks", "m_", "n_"))}


# --- (1) steady state and flat runs -----------------------------------------------------------

_tc = st.one_of(st.just(0.0), st.floats(0.02, 5.0))
_pos = st.floats(0.02, 5.0)


@st.composite
def pss_params(draw, cls):
    m, n = draw(st.sampled_from([(0, 0), (1, 1), (5, 1), (2, 2), (4, 2), (1, 8), (2, 3)]))
    p = dict(m_rtf=m, n_rtf=n, tw1_s=draw(_tc), tw2_s=draw(_tc), t6_s=draw(_tc),
             tw3_s=draw(_tc), tw4_s=draw(_tc), t7_s=draw(_tc), ks2=draw(st.floats(0, 2)),
             ks3=draw(st.floats(0, 2)), t8_s=draw(st.floats(0, 1)), t9_s=draw(_tc),
             ks1=draw(st.floats(0.5, 50)), t1_s=draw(_tc), t2_s=draw(_tc), t3_s=draw(_tc),
             t4_s=draw(_tc), vst_max_pu=draw(st.floats(0.05, 0.3)),
             vst_min_pu=-draw(st.floats(0.05, 0.3)))
    if cls is PSS2B:
        p.update(t10_s=draw(_tc), t11_s=draw(_tc), vs1_max_pu=0.1, vs1_min_pu=-0.1,
                 vs2_max_pu=2.0, vs2_min_pu=-2.0)
    return cls(**p)


@pytest.mark.slow
@pytest.mark.parametrize("cls", [PSS2A, PSS2B])
@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_steady_state_holds_and_a_flat_run_stays_flat(cls, data):
    m = data.draw(pss_params(cls))
    speed = data.draw(st.floats(-0.003, 0.003))
    pe = data.draw(st.floats(-0.5, 1.2))
    x0, f0 = _rest(m, jnp.asarray([speed, pe]))
    assert x0.shape == (m.n_states,)
    assert float(jnp.max(jnp.abs(f0))) < 1e-9
    _, xs, _ = simulate(m, (speed, pe), t_end=20.0, dt=0.01)
    assert np.max(np.abs(xs - np.asarray(x0)[None, :])) < 1e-6


def test_rest_output_is_zero_with_washouts_and_dc_gain_without():
    m = PSS2A(**PSS2A_DATA)
    x0 = m.initial_state(inputs(0.002, 0.9))
    assert float(m.output(x0, inputs(0.002, 0.9))) == 0.0
    no_wo = PSS2A(**{**PSS2A_DATA, "tw1_s": 0.0, "tw2_s": 0.0, "tw3_s": 0.0,
                     "vst_max_pu": 1.0, "vst_min_pu": -1.0})
    x0 = no_wo.initial_state(inputs(0.002, 0.9))
    # DC: KS1 [u1 + KS2 u2 (KS3 - 1)] = 10 * 0.002 with KS3 = 1
    assert float(no_wo.output(x0, inputs(0.002, 0.9))) == pytest.approx(0.02, abs=1e-12)


# --- (2) against the block diagram: steps and ramps of both inputs -----------------------------

CASES = {
    "PSS2A speed step": (PSS2A, PSS2A_DATA, (0.0, 0.8), (0.0005, 0.0), (0.0, 0.0)),
    "PSS2A power step": (PSS2A, PSS2A_DATA, (0.0, 0.8), (0.0, 0.05), (0.0, 0.0)),
    "PSS2A speed and power ramps": (PSS2A, PSS2A_FULL, (0.0, 0.6), (0.0, 0.0), (2e-4, 0.02)),
    "PSS2A 2x2 filter, power step": (PSS2A, PSS2A_FULL, (0.001, 0.6), (0.0, -0.1), (0.0, 0.0)),
    "PSS2B speed step": (PSS2B, PSS2B_DATA, (0.0, 0.8), (0.001, 0.0), (0.0, 0.0)),
    "PSS2B ramps into the input limit": (PSS2B, PSS2B_DATA, (0.0, 0.8), (0.0, 0.0),
                                         (4e-3, 0.01)),
}
MAX_DIFF = {}


@pytest.mark.parametrize("name", list(CASES))
def test_matches_block_diagram_reference(name):
    cls, p, u0, step, rate = CASES[name]
    m = cls(**p)
    t_end = 8.0
    y, _, _ = simulate(m, u0, step, rate, t_end)
    lim = None
    if cls is PSS2B:
        lim = ((p["vs1_min_pu"], p["vs1_max_pu"]), (p["vs2_min_pu"], p["vs2_max_pu"]))
    y_ref = reference_response(_params(m), u0, step, rate, t_end, lim)
    scale = np.max(np.abs(y_ref))
    assert scale > 1e-3
    diff = np.max(np.abs(y - y_ref))
    MAX_DIFF[name] = diff
    print(f"{name}: max |VST - reference| = {diff:.2e} pu (peak {scale:.3f} pu)")
    assert diff < 1e-6 * max(scale, 1.0)


# --- (3) a ramp-tracking filter that reduces to lags: closed form -----------------------------

@pytest.mark.parametrize("m_rtf,n_rtf", [(2, 1), (1, 3), (4, 2)])
def test_ramp_tracking_filter_of_lags_matches_closed_form(m_rtf, n_rtf):
    """T8 = 0: [1/(1 + s T9)^M]^N = 1/(1 + s T9)^(M N); step response of k cascaded lags
    1 - exp(-t/T) sum_{j<k} (t/T)^j / j!. Everything else bypassed: TW = 0, T6 = 0,
    KS2 = 0, the lead-lags off, KS1 = 1."""
    t9 = 0.3
    m = PSS2A(m_rtf=m_rtf, n_rtf=n_rtf, tw1_s=0.0, tw2_s=0.0, t6_s=0.0, tw3_s=0.0, tw4_s=0.0,
              t7_s=0.0, ks2=0.0, ks3=1.0, t8_s=0.0, t9_s=t9, ks1=1.0, t1_s=0.0, t2_s=0.0,
              t3_s=0.0, t4_s=0.0, vst_max_pu=1.0, vst_min_pu=-1.0)
    du = 0.01
    y, _, _ = simulate(m, (0.0, 0.5), (du, 0.0), t_end=5.0)
    t = DT * np.arange(1, len(y) + 1)
    k = m_rtf * n_rtf
    tau = t / t9
    closed = du * (1.0 - np.exp(-tau) * sum(tau ** j / math.factorial(j) for j in range(k)))
    assert np.max(np.abs(y - closed)) < 1e-9


# --- (4) limits --------------------------------------------------------------------------------

def test_output_and_input_limits_hold():
    m = PSS2A(**PSS2A_DATA)
    y, _, _ = simulate(m, (0.0, 0.8), (0.05, 0.0), t_end=3.0)          # a large speed step
    assert np.max(y) == pytest.approx(PSS2A_DATA["vst_max_pu"], abs=1e-15)
    assert np.all(y <= PSS2A_DATA["vst_max_pu"]) and np.all(y >= PSS2A_DATA["vst_min_pu"])
    y, _, _ = simulate(m, (0.0, 0.8), (-0.05, 0.0), t_end=3.0)
    assert np.min(y) == pytest.approx(PSS2A_DATA["vst_min_pu"], abs=1e-15)
    # PSS2B: input 1 limited at VS1MAX: a step of 0.05 acts as one of 0.02
    wide = dict(PSS2B_DATA, vst_max_pu=5.0, vst_min_pu=-5.0)
    b = PSS2B(**wide)
    y_big, _, _ = simulate(b, (0.0, 0.8), (0.05, 0.0), t_end=3.0)
    y_lim, _, _ = simulate(b, (0.0, 0.8), (0.02, 0.0), t_end=3.0)
    assert np.max(np.abs(y_big - y_lim)) < 1e-12
    assert np.max(np.abs(y_lim)) > 0.05


# --- (5) zero time constants: finite value and gradient ---------------------------------------

ZERO_T = dict(m_rtf=5, n_rtf=1, tw1_s=0.0, tw2_s=0.0, t6_s=0.0, tw3_s=0.0, tw4_s=0.0,
              t7_s=0.0, ks2=0.3, ks3=1.0, t8_s=0.0, t9_s=0.0, ks1=10.0, t1_s=0.0, t2_s=0.0,
              t3_s=0.0, t4_s=0.0, vst_max_pu=0.1, vst_min_pu=-0.1)


@pytest.mark.slow
@pytest.mark.parametrize("cls", [PSS2A, PSS2B])
def test_zero_time_constants_give_finite_values_and_gradients(cls):
    kw = dict(ZERO_T, **({"t10_s": 0.0, "t11_s": 0.0} if cls is PSS2B else {}))
    m = cls(**kw)
    inp = inputs(0.001, 0.8)

    def loss(model):
        x0 = model.initial_state(inp)
        x1 = x0 + 0.01 * model.vector_field(x0, inputs(0.002, 0.7))
        return model.output(x1, inputs(0.002, 0.7)) + jnp.sum(model.vector_field(x1, inp))

    val = loss(m)
    grads = eqx.filter_jit(eqx.filter_grad(loss))(m)
    leaves = jax.tree_util.tree_leaves(grads)
    assert np.isfinite(float(val))
    assert all(np.all(np.isfinite(np.asarray(g))) for g in leaves)
    # all blocks bypassed: VST = clip(KS1 [u1 + KS2 u2 (KS3 - 1)]) = clip(10 * 0.002)
    assert float(m.output(m.initial_state(inputs(0.002, 0.7)), inputs(0.002, 0.7))) == \
        pytest.approx(0.02, abs=1e-12)


def test_vmap_over_units_with_different_filter_orders():
    ms = [PSS2A(**dict(PSS2A_DATA, m_rtf=mm, n_rtf=nn)) for mm, nn in ((5, 1), (2, 4), (0, 0))]
    stacked = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *ms)
    inp = inputs(0.001, 0.8)
    x0 = jax.vmap(lambda m: m.initial_state(inp))(stacked)
    assert x0.shape == (3, 6 + RTF_MAX_STAGES + 2)
    d = jax.vmap(lambda m, x: m.vector_field(x, inputs(0.002, 0.8)))(stacked, x0)
    for k, m in enumerate(ms):
        np.testing.assert_allclose(d[k], m.vector_field(x0[k], inputs(0.002, 0.8)), atol=1e-15)


# --- (6) records --------------------------------------------------------------------------------

PSS2A_RECORD = (1, 0, 3, 0, 5, 1, 2, 2, 0, 2, 0, 2, 0.3, 1, 0.5, 0.1, 10, 0.15, 0.03, 0.2,
                0.04, 0.1, -0.1)
PSS2B_RECORD = PSS2A_RECORD[:21] + (0.1, 0.05, 0.02, -0.02, 1.25, -1.25, 0.1, -0.1)


def test_records_in_con_order():
    a = stabiliser_from_dyr("PSS2A", PSS2A_RECORD)
    assert isinstance(a, PSS2A) and not isinstance(a, PSS2B)
    assert (a.mode, a.remote_bus, a.mode2, a.remote_bus2) == (1, 0, 3, 0)
    assert (float(a.m_rtf), float(a.n_rtf)) == (5.0, 1.0)
    got = [float(getattr(a, f)) for f in ("tw1_s", "tw2_s", "t6_s", "tw3_s", "tw4_s", "t7_s",
                                          "ks2", "ks3", "t8_s", "t9_s", "ks1", "t1_s", "t2_s",
                                          "t3_s", "t4_s", "vst_max_pu", "vst_min_pu")]
    assert got == [float(v) for v in PSS2A_RECORD[6:]]
    b = stabiliser_from_dyr("PSS2B", PSS2B_RECORD)
    got = [float(getattr(b, f)) for f in ("t10_s", "t11_s", "vs1_max_pu", "vs1_min_pu",
                                          "vs2_max_pu", "vs2_min_pu", "vst_max_pu", "vst_min_pu")]
    assert got == [float(v) for v in PSS2B_RECORD[21:]]
    assert len(STABILISER_FIELDS["PSS2A"]) == 23 and len(STABILISER_FIELDS["PSS2B"]) == 29
    assert STABILISERS["PSS2B"] is PSS2B
    assert stabiliser_from_dyr("PSS2A", (1, 7, 3, 9) + PSS2A_RECORD[4:]).remote_input_at_terminal


BAD = [
    ("PSS2A", PSS2A_RECORD[:-1], "expected 23 constants"),
    ("PSS2B", PSS2A_RECORD, "expected 29 constants"),
    ("PSS2A", (1, 0, 3, 0, 2.5) + PSS2A_RECORD[5:], "ICON M must be an integer"),
    ("PSS2A", (1, 0, 3, 0, 3, 3) + PSS2A_RECORD[6:], "M N = 9.0 exceeds 8"),
    ("PSS2A", (1, 0, 3, 0, -1) + PSS2A_RECORD[5:], "must be an integer >= 0"),
    ("PSS2A", (7,) + PSS2A_RECORD[1:], "PSS2A: ICS1 must be an input code 1..6"),
    ("PSS2A", (1, 0, 8) + PSS2A_RECORD[3:], "PSS2A: ICS2 must be an input code 0..6"),
    ("PSS2A", PSS2A_RECORD[:6] + (-2.0,) + PSS2A_RECORD[7:], "PSS2A: TW1 must be >= 0"),
    ("PSS2A", PSS2A_RECORD[:21] + (-0.1, 0.1), "VSTMAX"),
    ("PSS2B", PSS2B_RECORD[:23] + (-0.02, 0.02) + PSS2B_RECORD[25:], "VS1MAX"),
    ("PSS2B", PSS2B_RECORD[:10] + ("x",) + PSS2B_RECORD[11:], "not a number"),
]


@pytest.mark.parametrize("model,constants,message", BAD, ids=[b[2] for b in BAD])
def test_bad_records_are_refused_in_one_line(model, constants, message):
    with pytest.raises(ValueError, match=message) as e:
        stabiliser_from_dyr(model, constants)
    assert "\n" not in str(e.value)


def test_real_records_of_activsg2000():
    if not ACTIVSG_DYR.exists():
        pytest.skip(f"{ACTIVSG_DYR} not present")
    from jaxdse._io.psse import read_dyr

    recs = [r for r in read_dyr(str(ACTIVSG_DYR)).records if r.model in ("PSS2A", "PSS2B")]
    if not recs:
        pytest.skip("ACTIVSg2000 has no PSS2A/PSS2B record (its stabilisers are IEEEST)")
    for r in recs:
        m = stabiliser_from_dyr(r.model, r.constants)
        x0 = m.initial_state(inputs(0.0, 0.7))
        assert float(jnp.max(jnp.abs(m.vector_field(x0, inputs(0.0, 0.7))))) < 1e-12
