"""PSS/E ICONs (switches between signal paths) are integer leaves, not static fields: records of
one model whose ICONs differ have one pytree structure, so a fleet's units of one model chain
stack into one vmapped call and one compiled program (the Texas 7k case had 57 structures from
24 chains while the inverter-based plants' flags were static, 24 since). Each family's stacked
call equals its members' own calls, away from rest and inside the limits the flags choose
between."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxdse._dyr.ibr_unit import IbrUnit
from jaxdse._dyr.unit import UnitInputs
from jaxdse._models.base import ExciterInputs, StabiliserInputs
from jaxdse._models.exciters import ESST1A, SCRX
from jaxdse._models.governors import GGOV1
from jaxdse._models.ibr import REECA1, REGCA1, REGCB1, REPCA1, WTTQA1
from jaxdse._models.stabilisers import IEEEST, PSS2A


def _stacked(modules):
    """One structure for all, and the modules stacked along a leading axis."""
    structures = {jax.tree_util.tree_structure(m) for m in modules}
    assert len(structures) == 1, structures
    return jax.tree.map(lambda *x: jnp.stack(x), *modules)


def _same(f, modules, *args):
    """f(module, *args) under vmap over the stacked modules equals each module's own call, and
    the members differ (the flags change the result)."""
    one = jax.jit(f)
    own = [one(m, *args) for m in modules]
    assert one._cache_size() == 1      # one compiled program for every member
    batched = jax.jit(jax.vmap(one, in_axes=(0, *[None] * len(args))))(_stacked(modules), *args)
    for k, o in enumerate(own):
        jax.tree.map(lambda b, x, k=k: np.testing.assert_allclose(b[k], x, rtol=1e-13, atol=1e-15),
                     batched, o)
    flat = [np.concatenate([np.ravel(x) for x in jax.tree.leaves(o)]) for o in own]
    assert len({tuple(np.round(x, 12)) for x in flat}) > 1


def test_inverter_based_plants():
    v, ang, p, q = 0.86, -0.3, 0.8, 0.25        # a low voltage, above REECA1's Vdip (0.8)
    u = UnitInputs(jnp.asarray(v * np.cos(ang)), jnp.asarray(v * np.sin(ang)), jnp.asarray(0.002),
                   jnp.asarray(0.0))
    i = np.conj((p + 1j * q) / (v * np.exp(1j * ang)))
    # Lvplsw, PFFLAG, VFLAG, QFLAG, PFLAG, PQFLAG, VCFlag, RefFlag, Fflag
    flags = ((1, 0, 1, 1, 0, 0, 1, 1, 1), (0, 1, 0, 0, 1, 1, 0, 0, 0), (1, 0, 0, 1, 0, 1, 0, 1, 1),
             (0, 0, 1, 0, 1, 0, 1, 0, 0))
    units = [IbrUnit(REGCA1(lvplsw=s),
                     REECA1(pfflag=pf, vflag=vf, qflag=qf, pflag=pl, pqflag=pq, i_max_pu=0.9),
                     REPCA1(vcflag=vc, refflag=rf, fflag=ff, kc=0.02))
             for s, pf, vf, qf, pl, pq, vc, rf, ff in flags]

    def f(unit, u, i_re, i_im):
        y0, refs = unit.initial_state(u, i_re, i_im)
        y = y0 * (1.0 + 0.05 * jnp.sin(jnp.arange(y0.shape[0], dtype=float)))   # away from rest
        return unit.vector_field(y, u, refs), unit.signals(y, u, refs)

    _same(f, units, u, i.real, i.imag)
    conv = [REGCB1(rateflag=r, pqflag=pq, t_e_s=0.01, re_pu=0.01, xe_pu=0.2, i_max_pu=0.8)
            for r, pq in ((0, 0), (1, 1), (1, 0))]
    _same(lambda c, s: (c.vector_field(s, 0.9, 0.7, 0.6), c.injection(s, 0.9)), conv,
          jnp.asarray([0.75, 0.3, 0.95, 0.9, 0.1]))
    torque = [WTTQA1(tflag=t) for t in (0, 1, 2)]
    _same(lambda m, s: m.outputs(s, 0.8, 1.1, 0.9), torque, jnp.asarray([0.85, 1.05, 0.7]))


def test_stabilisers():
    inputs = StabiliserInputs(*(jnp.asarray(x) for x in (0.01, 0.004, 0.8, -0.05, 1.02, 0.3)))
    state = jnp.linspace(0.1, 0.7, 7)
    _same(lambda m, s, i: (m.vector_field(s, i), m.output(s, i)),
          [IEEEST(mode=k, remote_bus=b, t5_s=1.0, t6_s=1.5) for k, b in ((1, 0), (3, 7), (4, 0), (6, 2))],
          state, inputs)
    pss = [PSS2A(mode=1, mode2=3), PSS2A(mode=2, mode2=0), PSS2A(mode=5, mode2=4)]
    _same(lambda m, s, i: (m.vector_field(s, i), m.output(s, i)), pss,
          jnp.linspace(0.05, 0.6, pss[0].n_states), inputs)


def test_governors_and_exciters():
    ggov = [GGOV1(rselect=r, flag=f) for r, f in ((1, 1), (-1, 0), (-2, 1))]
    state = jnp.linspace(0.3, 0.9, 11)
    _same(lambda m, s: (m.vector_field(s, 0.004, 0.8), m.steady_state(0.8, 0.004),
                        m.reference_from_steady(0.7, 0.004)), ggov, state)
    inputs = ExciterInputs(*(jnp.asarray(x) for x in (0.97, 0.9, 0.3, 0.7, -0.2, 1.8, 0.02)))
    _same(lambda m, s, i: (m.vector_field(s, i, 1.05), m.efd(s, i, 1.05)),
          [SCRX(cswitch=0), SCRX(cswitch=1)], jnp.asarray([1.5, 2.0]), inputs)
    st = [ESST1A(vos=1, uel=1, klr=1.0, ilr_pu=1.2), ESST1A(vos=2, uel=3, klr=1.0, ilr_pu=1.2)]
    _same(lambda m, s, i: (m.vector_field(s, i, 1.05), m.efd(s, i, 1.05)), st,
          jnp.asarray([0.96, 0.1, 0.2, 2.0, 0.01]), inputs)


def test_bad_icons_are_refused_in_their_own_names():
    with pytest.raises(ValueError, match="REECA1.qflag must be 0 or 1, got 2"):
        REECA1(qflag=2)
    with pytest.raises(ValueError, match="WTTQA1.tflag must be 0, 1 or 2, got 3"):
        WTTQA1(tflag=3)
    with pytest.raises(ValueError, match="GGOV1.flag must be 0 or 1, got 4"):
        GGOV1(flag=4)
    with pytest.raises(ValueError, match="IEEEST.mode must be an input code 1..6, got 7"):
        IEEEST(mode=7)
