"""REGFM_A1 (droop-controlled grid-forming inverter) against a plain SciPy integration of its
block diagram written here from PNNL-35110 (scalar Python, not the module), with the terminal
voltage phasor imposed: a voltage step with a frequency ramp (the Pmax controller reached), and a
deep voltage dip (the current limit Imax, the Qmax controller and the Emax limit reached); a flat
run stays flat; the record reads in PSS/E order with its coupling impedance from ZSORCE.

One compiled program, shared by the three runs (one shape). The largest differences are printed
(``pytest -s``) and asserted below 1e-5 pu.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from gfm_drive import ANG, P0, Q0, TS, V0, W0, away, nw, simulate, solve_pieces, theta_of, v_of
from gfm_drive import runs as drive_runs

import jaxdse as jd
from jaxdse._dyr.gfm_unit import GfmUnit
from jaxdse._models.ibr import REGFM_A1, GfmInputs, ibr_from_dyr

F_RATE = -(0.1 / 60.0) / 0.5  # -0.1 Hz in 0.5 s [pu/s]: P rises into the Pmax controller
RUNS = drive_runs(F_RATE)
# VFlag = 1 (a voltage PI), QVFlag = 0; Pmax between P0 and P0 + the droop's answer to -0.1 Hz
C = dict(
    vflag=1,
    qvflag=0,
    tpf=0.02,
    tqf=0.03,
    tvf=0.01,
    imax=1.3,
    emax=1.15,
    emin=0.0,
    pmax=0.8,
    pmin=0.0,
    qmax=0.45,
    qmin=-0.45,
    mp=0.01,
    mq=0.05,
    kppmax=0.01,
    kipmax=0.1,
    kpqmax=3.0,
    kiqmax=20.0,
    kpv=0.2,
    kiv=6.0,
    re=0.005,
    xe=0.15,
)
RECORD = [
    C[k]
    for k in (
        "vflag",
        "qvflag",
        "tpf",
        "tqf",
        "tvf",
        "imax",
        "emax",
        "emin",
        "pmax",
        "pmin",
        "qmax",
        "qmin",
        "mp",
        "mq",
        "kppmax",
        "kipmax",
        "kpqmax",
        "kiqmax",
        "kpv",
        "kiv",
    )
]


def _module():
    m = ibr_from_dyr("REGFM_A1", RECORD)
    return eqx.tree_at(lambda c: (c.re_pu, c.xe_pu), m, (jnp.asarray(C["re"]), jnp.asarray(C["xe"])))


# --- the block diagram, written out (PNNL-35110) ------------------------------------------------


def _reference(steps, ramps):
    """P, Q out of the terminal at TS, by solve_ivp, and which limits were reached."""
    c = C
    z = complex(c["re"], c["xe"])
    v0 = V0 * np.exp(1j * ANG)
    i0 = np.conj((P0 + 1j * Q0) / v0)
    e0 = v0 + z * i0
    pref, qref, vref = P0, Q0, V0  # VFlag = 1: Vcmd = |V| at rest; QVFlag = 0
    reached = set()

    def source(x, t):
        delta, xe, pm, qm, vm, xpmax, xpmin, xqmax, xqmin = x
        dwp = min(0.0, c["kppmax"] * (c["pmax"] - pm) + xpmax) + max(
            0.0, c["kppmax"] * (c["pmin"] - pm) + xpmin
        )
        dw = c["mp"] * (pref - pm) + dwp
        dvq = min(0.0, c["kpqmax"] * (c["qmax"] - qm) + xqmax) + max(
            0.0, c["kpqmax"] * (c["qmin"] - qm) + xqmin
        )
        vcmd = vref + c["mq"] * (qref - qm) + dvq
        e_raw = c["kpv"] * (vcmd - vm) + xe
        e = min(max(e_raw, c["emin"]), c["emax"])
        v = v_of(t, steps) * np.exp(1j * theta_of(t, ramps))
        cur = (e * np.exp(1j * delta) - v) / z
        if abs(cur) > c["imax"]:
            cur *= c["imax"] / abs(cur)
            reached.add("Imax")
        if e_raw > c["emax"]:
            reached.add("Emax")
        if dwp < 0:
            reached.add("Pmax")
        if dvq < 0:
            reached.add("Qmax")
        s = v * np.conj(cur)
        return dw, vcmd, s, abs(v)

    def rhs(t, x):
        delta, xe, pm, qm, vm, xpmax, xpmin, xqmax, xqmin = x
        dw, vcmd, s, vt = source(x, t)
        return [
            W0 * dw,
            nw(xe, c["kiv"] * (vcmd - vm), c["emin"], c["emax"]),
            (s.real - pm) / c["tpf"],
            (s.imag - qm) / c["tqf"],
            (vt - vm) / c["tvf"],
            nw(xpmax, c["kipmax"] * (c["pmax"] - pm), -np.inf, 0.0),
            nw(xpmin, c["kipmax"] * (c["pmin"] - pm), 0.0, np.inf),
            nw(xqmax, c["kiqmax"] * (c["qmax"] - qm), -np.inf, 0.0),
            nw(xqmin, c["kiqmax"] * (c["qmin"] - qm), 0.0, np.inf),
        ]

    x = np.array([np.angle(e0), abs(e0), P0, Q0, V0, 0.0, 0.0, 0.0, 0.0])
    ys = solve_pieces(rhs, x, steps, ramps)
    s = np.array([source(y, t)[2] for t, y in zip(TS, ys)])
    return s.real, s.imag, reached


@pytest.fixture(scope="module")
def runs():
    m = _module()
    out = {}
    for name, (steps, ramps) in RUNS.items():
        ys, sig, y0 = simulate(m, jnp.asarray(TS), jnp.asarray(steps), jnp.asarray(ramps))
        ref = _reference(steps, ramps) if name != "flat" else None
        out[name] = (np.asarray(ys), sig, np.asarray(y0), ref)
    return m, out


@pytest.mark.parametrize("name, limits", [("step_ramp", {"Pmax"}), ("dip", {"Imax", "Qmax", "Emax"})])
def test_matches_the_scipy_block_diagram(runs, name, limits):
    _, out = runs
    _, sig, _, (p_ref, q_ref, reached) = out[name]
    far = away(*RUNS[name])
    dp = np.max(np.abs(np.asarray(sig.p_pu) - p_ref)[far])
    dq = np.max(np.abs(np.asarray(sig.q_pu) - q_ref)[far])
    print(
        f"\nREGFM_A1 {name}: largest difference from SciPy {max(dp, dq):.2e} pu (P {dp:.2e}, "
        f"Q {dq:.2e}); limits reached: {sorted(reached)}"
    )
    assert max(dp, dq) < 1e-5
    assert limits <= reached
    assert np.ptp(p_ref) > 0.05 and np.ptp(q_ref) > 0.05


def test_a_flat_run_stays_flat(runs):
    m, out = runs
    ys, sig, y0, _ = out["flat"]
    assert np.max(np.abs(np.asarray(sig.p_pu) - P0)) < 1e-9  # (the solver's rtol 1e-10)
    assert np.max(np.abs(np.asarray(sig.q_pu) - Q0)) < 1e-9
    assert np.max(np.abs(ys - y0)) < 1e-9
    assert float(m.h_s) == pytest.approx(C["tpf"] / (2 * C["mp"]))


@pytest.mark.parametrize("vflag, qvflag", [(0, 0), (0, 1), (1, 0), (1, 1)])
def test_every_flag_combination_starts_at_rest(vflag, qvflag):
    """At the initial state every derivative is 0 (round-off) and the source delivers P, Q."""
    m = eqx.tree_at(lambda c: (c.vflag, c.qvflag), _module(), (jnp.asarray(vflag), jnp.asarray(qvflag)))
    v = V0 * np.exp(1j * ANG)
    i = np.conj((P0 + 1j * Q0) / v)
    u = GfmInputs(jnp.asarray(v.real), jnp.asarray(v.imag))
    y0, refs = m.initial_state(u, jnp.asarray(i.real), jnp.asarray(i.imag))
    assert np.max(np.abs(np.asarray(m.vector_field(y0, u, refs)))) < 1e-12
    s = m.signals(y0, u, refs)
    assert float(s.p_pu) == pytest.approx(P0, abs=1e-12) and float(s.q_pu) == pytest.approx(Q0, abs=1e-12)
    assert float(s.omega_pu) == 1.0
    assert float(refs.q_ref_pu) == (0.0 if qvflag else pytest.approx(Q0))


def test_the_droop_sets_the_frequency_response(runs):
    """Within its limits, P answers a frequency deviation df by -df / mp (the droop), and the
    Pmax controller holds P at Pmax beyond them: after the -0.1 Hz ramp, P settles at Pmax."""
    _, out = runs
    _, sig, _, _ = out["step_ramp"]
    p = np.asarray(sig.p_pu)
    k = np.searchsorted(TS, 1.5) - 1
    assert p[k] == pytest.approx(C["pmax"], abs=0.02)
    assert P0 + (0.1 / 60.0) / C["mp"] > C["pmax"]  # the droop alone would pass it


def test_record_reads_in_psse_order_and_names_its_constants():
    m = ibr_from_dyr("REGFM_A1", RECORD)
    assert int(m.vflag) == 1 and float(m.mp) == C["mp"] and float(m.kiv) == C["kiv"]
    assert float(m.i_max_pu) == C["imax"] and float(m.q_min_pu) == C["qmin"]
    with pytest.raises(ValueError, match="mp"):
        ibr_from_dyr("REGFM_A1", RECORD[:12] + [0.0] + RECORD[13:])
    with pytest.raises(ValueError, match="expected 20 values"):
        ibr_from_dyr("REGFM_A1", RECORD[:-1])
    with pytest.raises(ValueError, match="VFlag"):
        ibr_from_dyr("REGFM_A1", [2] + RECORD[1:])
    assert isinstance(GfmUnit(m).converter, REGFM_A1)
    assert jd.REGFM_A1 is REGFM_A1
