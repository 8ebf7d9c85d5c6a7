"""The jaxdse observer against a plain NumPy loop of the same equations (benchmarks/numpy_reference)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from numpy_reference import observer_loop  # benchmarks/ (pytest pythonpath)

import jaxdse as jd
from jaxdse._core.drem import DremInputs, run_observer
from jaxdse._core.front_end import front_end, reference_torque


def test_observer_matches_numpy_loop(ambient, plant):
    rec = ambient.recording
    n = 1500  # 30 s
    rec = jd.Recording(t_s=rec.t_s[:n], v_mag_pu=rec.v_mag_pu[:n], v_ang_rad=rec.v_ang_rad[:n],
                       i_mag_pu=rec.i_mag_pu[:n], i_ang_rad=rec.i_ang_rad[:n], f_hz=rec.f_hz[:n])
    cfg = jd.ObserverConfig(gamma1=2000.0, gamma2=1500.0, k_ext=5.0, lambda2=5.0)
    fe = eqx.filter_jit(front_end)(rec, plant)  # one program, not one per operation
    t_ref = reference_torque(rec.t_s, fe, plant.governor, jd.Settings())
    delta = fe.alg.delta_rad - fe.alg.delta_rad[0]
    inputs = DremInputs(delta, fe.alg.t_e_pu, fe.dw, jnp.zeros(n))
    run = jax.jit(lambda *a: run_observer(*a, jd.Integrator.fast(), False, x2_meas=fe.x2_meas,
                                             save_trajectory=True))
    traj = run(rec.t_s, inputs, fe.x2_meas[0], t_ref, cfg, plant.governor).trajectory
    as_dict = {f: float(getattr(cfg, f)) for f in cfg.__dataclass_fields__}
    gov = {f: float(getattr(plant.governor, f)) for f in plant.governor.__dataclass_fields__}
    theta = observer_loop(np.asarray(rec.t_s), np.asarray(delta), np.asarray(fe.alg.t_e_pu),
                          np.asarray(fe.dw), float(fe.x2_meas[0]), float(t_ref), as_dict, gov)
    np.testing.assert_allclose(np.asarray(traj.theta), theta, rtol=1e-9, atol=1e-10)
    assert abs(theta[-1, 1] - theta[0, 1]) > 1.0  # the estimate moved: the comparison means something
