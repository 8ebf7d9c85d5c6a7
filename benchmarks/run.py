"""Side-by-side benchmarks on the same synthetic recordings (issue 4). Writes results.json and
results.md next to this file; README quotes the table.

    python benchmarks/run.py [--quick]

* jaxdse: the full pipeline (mapping, algebraic observer, governor, DREM/I&I) over batches of
  recordings (``estimate_batch``, ``keep="final"``, no playback, ``Integrator.fast()``), batch
  sharded over the 2 CPU cores as 2 XLA host devices. Compile time apart from run time.
* NumPy: the observer time loop by hand (``numpy_reference.py``), same equations.
* dynamax UKF and filterpy UKF on the 3rd-order model, driven by the same terminal voltage,
  Ef and Tm, measuring P_t and Q_t: state estimation (a1, a2 known), and joint state and
  parameter estimation (augmented state with a1, a2).
* jaxdse batch identification (``identify``) on the same recordings at the joint UKF's batch:
  the default settings and the sandwich interval without bootstrap or filter spread.
* Gradient cost: value-and-grad of the tuning loss over the forward loss, in forward and
  reverse mode, for 1, 4 and 16 recordings.
* Peak memory (separate processes, recording memory-mapped from .npy files written by another
  process): 1 h at 50 frames/s x 1024 configurations (final values only), and a 24 h
  recording in chunks (physical simulations of 1 h and 24 h; the 24 h one takes ~4 min).
"""

from __future__ import annotations

import os

os.environ.setdefault("XLA_FLAGS", "--xla_force_host_platform_device_count=2")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from jax.flatten_util import ravel_pytree  # noqa: E402
from numpy_reference import observer_loop  # noqa: E402  (beside this script)

import jaxdse as jd  # noqa: E402

HERE = Path(__file__).parent

try:  # benchmark extras: pip install -e .[bench]
    from dynamax.nonlinear_gaussian_ssm import ParamsNLGSSM, UKFHyperParams, unscented_kalman_filter
except ImportError:  # pragma: no cover
    ParamsNLGSSM = None

OTHER_SCRIPTS = ("fleet_scaling", "dyr_playback", "identify_cost")
"""Keys of results.json that other benchmark scripts write (kept as they are)."""
FAST = jd.Settings(observer_integrator=jd.Integrator.fast(), keep="final", playback=False)
IDENTIFY_CHUNK = 128
"""Recordings per call of the batch identification (bounds the bootstrap's memory)."""


def timed(fn, repeat=3):
    """(first call s, best of ``repeat`` later calls s, result)."""
    t = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return first, best, out


def recordings(plant, n_distinct, duration_s):
    sims = [jd.simulate(plant, jd.Scenario(duration_s=duration_s, p_pu=0.45 + 0.5 * k / n_distinct,
                                           seed=200 + k)) for k in range(n_distinct)]
    return sims


def tile(sims, batch):
    recs = jd.stack_recordings([s.recording for s in sims])
    idx = np.arange(batch) % len(sims)
    return jax.tree_util.tree_map(lambda x: np.asarray(x)[idx], recs), idx


# --- UKF baselines: the 3rd-order model (paper Eqs. 1-3) --------------------------------------

def ukf_inputs(sim, plant):
    """Terminal |V|, angle, Ef, Tm (same front end as jaxdse) and measured P_t, Q_t."""
    tr = jax.jit(jd.estimate)(sim.recording, plant, jd.ObserverConfig(), jd.Settings()).trajectories
    u = np.stack([tr.v_t_pu, tr.theta_t_rad, tr.e_f_pu, tr.t_m_pu], axis=1)
    y = np.stack([tr.p_t_pu, tr.q_t_pu], axis=1)
    x0 = np.array([0.0, float(tr.x2_meas_rad_s[0]), float(tr.e_q1_pu[0])])
    return u, y, x0


def model_step(x, u, a1, a2, m, dt, xp=jnp):
    """One Heun step of (delta, x2, E'q) with inputs held over the sample interval."""
    def f(x):
        v_d, v_q = xp.sin(x[0] - u[1]) * u[0], xp.cos(x[0] - u[1]) * u[0]
        i_d, i_q = jd.stator_currents(x[2], v_d, v_q, m)
        t_e = jd.electrical_torque(x[2], i_d, i_q, m)
        return xp.stack([x[1], -a1 * x[1] + a2 * (u[3] - t_e),
                         (-x[2] - (m.xd_pu - m.xd1_pu) * i_d + u[2]) / m.td01_s])
    k1 = f(x)
    k2 = f(x + dt * k1)
    return x + 0.5 * dt * (k1 + k2)


def model_output(x, u, m, xp=jnp):
    v_d, v_q = jd.terminal_dq(u[0], u[1], x[0])
    i_d, i_q = jd.stator_currents(x[2], v_d, v_q, m)
    p, q = jd.terminal_power(v_d, v_q, i_d, i_q)
    return xp.stack([p, q])


def dynamax_ukf(u, y, x0, m, dt, a1, a2, joint):
    nx = 5 if joint else 3

    def dyn(x, uu):
        pa1, pa2 = (x[3], x[4]) if joint else (a1, a2)
        nxt = model_step(x[:3], uu, pa1, pa2, m, dt)
        return jnp.concatenate([nxt, x[3:]]) if joint else nxt

    def emit(x, uu):
        return model_output(x[:3], uu, m)

    q = jnp.diag(jnp.array([1e-8, 1e-4, 1e-7] + ([1e-6, 1e-4] if joint else [])))
    p0 = jnp.diag(jnp.array([1e-4, 1e-2, 1e-4] + ([0.25, 400.0] if joint else [])))
    m0 = jnp.concatenate([x0, jnp.array([0.5, 40.0])]) if joint else x0
    params = ParamsNLGSSM(initial_mean=m0, initial_covariance=p0, dynamics_function=dyn,
                          dynamics_covariance=q, emission_function=emit,
                          emission_covariance=jnp.eye(2) * 1e-6)
    post = unscented_kalman_filter(params, y, UKFHyperParams(), inputs=u,
                                   output_fields=["filtered_means"])
    return post.filtered_means[:, :nx]


def filterpy_ukf(u, y, x0, m, dt, a1, a2, joint, n=None):
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    mn = jax.tree_util.tree_map(lambda v: float(v), m)  # NumPy floats for the model functions
    nx = 5 if joint else 3
    state = {"u": u[0]}

    def fx(x, dt_):
        pa1, pa2 = (x[3], x[4]) if joint else (a1, a2)
        nxt = model_step(x[:3], state["u"], pa1, pa2, mn, dt_, xp=np)
        return np.concatenate([nxt, x[3:]]) if joint else nxt

    def hx(x):
        return model_output(x[:3], state["u"], mn, xp=np)

    ukf = UnscentedKalmanFilter(dim_x=nx, dim_z=2, dt=dt, fx=fx, hx=hx,
                                points=MerweScaledSigmaPoints(nx, alpha=1.0, beta=0.0, kappa=0.0))
    ukf.x = np.concatenate([x0, [0.5, 40.0]]) if joint else x0.copy()
    ukf.P = np.diag([1e-4, 1e-2, 1e-4] + ([0.25, 400.0] if joint else []))
    ukf.Q = np.diag([1e-8, 1e-4, 1e-7] + ([1e-6, 1e-4] if joint else []))
    ukf.R = np.eye(2) * 1e-6
    n = n or len(y)
    out = np.empty((n, nx))
    for k in range(n):
        if k:
            state["u"] = u[k - 1]
            ukf.predict()
        state["u"] = u[k]
        ukf.update(y[k])
        out[k] = ukf.x
    return out


# --- memory cases, each in its own process ----------------------------------------------------

FIELDS = ("t_s", "v_mag_pu", "v_ang_rad", "i_mag_pu", "i_ang_rad", "f_hz")


def peak_rss_gib():
    """This process's own peak resident set (VmHWM). Not ``ru_maxrss``: Linux carries that
    across fork and exec, so a child of a large parent reports the parent's peak."""
    with open("/proc/self/status") as f:
        kib = next(int(line.split()[1]) for line in f if line.startswith("VmHWM:"))
    return kib / 2**20


def memory_case(case, folder):
    """Peak RSS of one case. The recording is read from .npy files memory-mapped, as a long file
    would be; it was simulated and written by another process (``prepare``), so the peak is
    the estimation's own (plus the JAX runtime, reported as ``baseline_rss_gib``)."""
    folder = Path(folder)
    if case.startswith("prepare"):
        # A physical simulation (ambient fluctuations, no seams), ~4 min for 24 h. A 600 s
        # simulation tiled to 24 h was tried first: each seam jumps the rotor angle against
        # the voltage angle, and a2_hat drifted from 26 to 3 within 6 h on it.
        sim = jd.simulate(jd.Plant(), jd.Scenario(duration_s=float(case.split(":")[1]) * 3600.0, seed=7))
        rec = sim.recording
        folder.mkdir(parents=True, exist_ok=True)
        for k in FIELDS:
            np.save(folder / f"{k}.npy", np.asarray(getattr(rec, k)))
        np.save(folder / "a2_true.npy", np.asarray(sim.truth.a2))
        return
    rec = jd.Recording(**{k: np.load(folder / f"{k}.npy", mmap_mode="r") for k in FIELDS})
    plant = jd.Plant()
    jax.block_until_ready(jnp.zeros(1) + 1)
    baseline = peak_rss_gib()
    t = time.perf_counter()
    if case == "1h_x1024":
        cfgs = jd.stack([jd.ObserverConfig(gamma1=g, gamma2=g) for g in np.geomspace(400, 4000, 1024)])
        out = jd.estimate_batch(rec, plant, cfgs, FAST)
        extra = {"samples": int(rec.t_s.shape[0]), "configs": 1024, "a2_median": float(np.median(out.a2))}
    else:
        st = jd.Settings(observer_integrator=jd.Integrator.fast(), playback_integrator=jd.Integrator.fast(),
                         keep="final")
        out = jd.estimate_stream(rec, plant, jd.ObserverConfig(), st, chunk_s=1800.0)
        a2_true = float(np.load(folder / "a2_true.npy"))
        a2_hat = np.asarray(out.a2_hat)
        settled = np.asarray(out.time_s) >= 3600.0
        extra = {"samples": int(rec.t_s.shape[0]), "a2": float(out.a2), "a2_true": a2_true,
                 "a2_max_error_percent_after_1h": float(np.max(np.abs(a2_hat[settled] / a2_true - 1)) * 100),
                 "converged": bool(out.converged), "solver_ok": bool(out.solver_ok)}
    wall = time.perf_counter() - t
    peak = peak_rss_gib()
    print(json.dumps({"peak_rss_gib": peak, "baseline_rss_gib": baseline, "wall_s": wall, **extra}))


def run_memory(case, hours):
    def call(arg, folder):
        out = subprocess.run([sys.executable, __file__, "--memory", arg, "--folder", folder],
                             capture_output=True, text=True,
                             env={**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=2"})
        if out.returncode:
            raise RuntimeError(out.stderr[-3000:])
        return out.stdout

    with tempfile.TemporaryDirectory() as folder:
        call(f"prepare:{hours}", folder)
        return json.loads(call(case, folder).strip().splitlines()[-1])


# --- main -------------------------------------------------------------------------------------

def gradient_cost(sims, plant, cfg, sizes):
    """Value-and-grad of the tuning loss over its forward pass, forward and reverse mode.

    The three are timed interleaved (best of 15 each), so that a slow spell of the machine
    hits all of them. ``grad_over_forward`` is the mode ``jd.tune`` picks by default
    (``autodiff="auto"``) for 4 training recordings, as in ``experiments/tuning``.
    """
    table = {}
    for n in sizes:
        recs = jd.stack_recordings([sims[k % len(sims)].recording for k in range(n)])
        a2 = jnp.asarray([float(sims[k % len(sims)].truth.a2) for k in range(n)])

        def loss(u, recs, a2):  # the data as arguments, as in jd.tune (else XLA constant-folds)
            return jd.tuning_loss(unravel(u), recs, plant, jd.Settings.fast(), a2)

        def fwd_mode(u, recs, a2):
            return jd.forward_mode(lambda v: loss(v, recs, a2))(u)

        fns = {"forward": jax.jit(loss), "fwd": jax.jit(jax.value_and_grad(fwd_mode)),
               "bwd": jax.jit(jax.value_and_grad(loss))}
        u0, unravel = ravel_pytree(cfg)
        times = {k: [] for k in fns}
        for _ in range(16):  # the first round compiles and warms up
            for k, f in fns.items():
                t = time.perf_counter()
                jax.block_until_ready(f(u0, recs, a2))
                times[k].append(time.perf_counter() - t)
        best = {k: min(v[1:]) for k, v in times.items()}
        table[str(n)] = {"forward_s": best["forward"], "fwd_over_forward": best["fwd"] / best["forward"],
                         "bwd_over_forward": best["bwd"] / best["forward"]}
        print(f"gradient, {n} recordings: forward {best['forward'] * 1e3:.1f} ms, value-and-grad "
              f"fwd {best['fwd'] / best['forward']:.2f}x, bwd {best['bwd'] / best['forward']:.2f}x",
              flush=True)
    mode = "fwd"  # what jd.tune(autodiff="auto") picks for 4 training recordings
    return {"grad_over_forward": table["4"][f"{mode}_over_forward"], "grad_mode": mode,
            "grad_over_forward_reverse": table["4"]["bwd_over_forward"], "grad_by_recordings": table}


def sharding():
    """The batch axis split over every device."""
    mesh = jax.sharding.Mesh(np.array(jax.devices()), ("batch",))
    return jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("batch"))


def dynamax_entry(sims, plant, data, batch, joint):
    """dynamax's UKF (state, or ``joint`` state and a1, a2) on ``batch`` tiled recordings
    (``data``: their :func:`ukf_inputs`): speed and accuracy."""
    m = plant.machine
    n_t = sims[0].recording.t_s.shape[0]
    dt = float(sims[0].recording.t_s[1] - sims[0].recording.t_s[0])
    x2_true = np.stack([np.asarray(s.truth.x2_rad_s) for s in sims])
    a1_true = np.array([float(s.truth.a1) for s in sims])
    a2_true = np.array([float(s.truth.a2) for s in sims])
    idx = np.arange(batch) % len(sims)
    arrays = [np.stack([d[k] for d in data]) for k in range(3)] + [a1_true, a2_true]
    put = [jax.device_put(x[idx], sharding()) for x in arrays]
    fn = jax.jit(jax.vmap(lambda u, y, x0, a1, a2: dynamax_ukf(u, y, x0, m, dt, a1, a2, joint)))
    first, best, out = timed(lambda: jax.block_until_ready(fn(*put)), repeat=1)
    out = np.asarray(out)[: len(sims)]
    entry = {"batch": batch, "gen_samples_per_s": batch * n_t / best, "compile_s": first - best,
             "x2_rmse_rad_s_median": float(np.median(np.sqrt(np.mean(
                 (out[:, n_t // 2:, 1] - x2_true[:, n_t // 2:]) ** 2, axis=1))))}
    if joint:
        entry["a2_error_percent_median_abs"] = float(np.median(np.abs(
            100 * (out[:, -1, 4] - a2_true) / a2_true)))
    return entry


def identify_entry(sims, plant, batch, ids, interval=True):
    """``jd.identify`` with ``ids`` on ``batch`` tiled recordings, vmapped in calls of
    ``IDENTIFY_CHUNK`` and sharded over the devices: speed and the median a2 error. The output is
    a2 and, with ``interval``, the 95 % interval of H, so that XLA cannot drop the interval's
    work (the bootstrap, the filter spread) as dead code."""
    recs, _ = tile(sims, batch)
    n_t = sims[0].recording.t_s.shape[0]
    a2_true = np.array([float(s.truth.a2) for s in sims])

    def out_of(r):
        i = jd.identify(r, plant, jd.ObserverConfig(), jd.Settings(), ids)
        return (i.a2, i.h_ci95) if interval else (i.a2,)

    one = jax.jit(jax.vmap(out_of))
    chunks = [jax.device_put(jax.tree_util.tree_map(lambda x, k=k: x[k:k + IDENTIFY_CHUNK], recs), sharding())
              for k in range(0, batch, IDENTIFY_CHUNK)]

    def fn():
        parts = [jax.device_get(one(c)) for c in chunks]
        return jax.tree_util.tree_map(lambda *x: np.concatenate(x), *parts)

    first, best, out = timed(fn, repeat=1)
    return {"batch": batch, "gen_samples_per_s": batch * n_t / best, "compile_s": first - best,
            "a2_error_percent_median_abs": float(np.median(np.abs(
                100 * (np.asarray(out[0])[: len(sims)] - a2_true) / a2_true)))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="small sizes (a smoke test, not the table)")
    ap.add_argument("--memory-only", action="store_true",
                    help="re-measure only the two memory cases into the existing results.json")
    ap.add_argument("--keep-memory", action="store_true",
                    help="keep the memory figures of the existing results.json (skips ~5 min)")
    ap.add_argument("--memory", help=argparse.SUPPRESS)
    ap.add_argument("--folder", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.memory:
        return memory_case(args.memory, args.folder)
    if args.memory_only:
        res = json.loads((HERE / "results.json").read_text())
        measure_memory(res)
        (HERE / "results.json").write_text(json.dumps(res, indent=2))
        return write_table(res, HERE / "results.md")
    plant = jd.Plant()
    m = plant.machine
    duration = 20.0 if args.quick else 60.0
    batches = (1, 64) if args.quick else (1, 64, 1024, 4096)
    sims = recordings(plant, 8, duration)
    n_t = sims[0].recording.t_s.shape[0]
    dt = float(sims[0].recording.t_s[1] - sims[0].recording.t_s[0])
    cfg = jd.ObserverConfig()
    res = {"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
           "devices": len(jax.devices()), "jax": jax.__version__, "samples_per_recording": int(n_t),
           "frame_rate_hz": 1 / dt, "throughput_gen_samples_per_s": {}, "compile_s": {}}
    print(f"{len(jax.devices())} devices; {n_t} samples per recording", flush=True)

    # jaxdse throughput
    for b in batches:
        recs, idx = tile(sims, b)
        a2 = np.array([float(sims[k].truth.a2) for k in idx])
        first, best, out = timed(lambda recs=recs, a2=a2, b=b: jd.estimate_batch(
            recs, plant, cfg, FAST, None, a2, chunk=1024 if b > 1024 else None))
        res["throughput_gen_samples_per_s"][str(b)] = b * n_t / best
        res["compile_s"][str(b)] = first - best
        print(f"jaxdse batch {b}: {b * n_t / best / 1e6:.2f} M gen-samples/s (compile {first - best:.1f} s)",
              flush=True)
    # accuracy of jaxdse on the distinct recordings (fast and adaptive integrators)
    recs, idx = tile(sims, len(sims))
    a2_true = np.array([float(s.truth.a2) for s in sims])
    acc = {}
    for label, st in (("fast (Heun, 1 step/sample)", FAST),
                      ("adaptive (Tsit5)", jd.Settings(keep="final", playback=False))):
        e = jd.estimate_batch(recs, plant, cfg, st, None, a2_true)
        acc[label] = {"a2_error_percent_median_abs": float(np.median(np.abs(100 * (e.a2 - a2_true) / a2_true)))}  # noqa: E501
    traj = jd.estimate_batch(recs, plant, cfg, jd.Settings(observer_integrator=jd.Integrator.fast(),
                                                           playback=False)).trajectories
    x2_true = np.stack([np.asarray(s.truth.x2_rad_s) for s in sims])
    acc["fast (Heun, 1 step/sample)"]["x2_rmse_rad_s_median"] = float(np.median(
        np.sqrt(np.mean((traj.x2_hat_rad_s - x2_true)[:, n_t // 2:] ** 2, axis=1))))
    res["jaxdse_accuracy"] = acc

    # NumPy reference on recording 0
    rec0 = sims[0].recording
    front = jax.jit(jd.estimate, static_argnums=3)(rec0, plant, cfg, jd.Settings(playback=False))
    tr = front.trajectories
    cfg_d = {f: float(getattr(cfg, f)) for f in cfg.__dataclass_fields__}
    gov_d = {f: float(getattr(plant.governor, f)) for f in plant.governor.__dataclass_fields__}
    t = time.perf_counter()
    theta = observer_loop(np.asarray(rec0.t_s), np.asarray(tr.delta_rad), np.asarray(tr.t_e_pu),
                          np.asarray(tr.x2_meas_rad_s / m.omega_s), float(tr.x2_meas_rad_s[0]),
                          float(front.t_ref_pu), cfg_d, gov_d)
    res["numpy_reference_gen_samples_per_s"] = n_t / (time.perf_counter() - t)
    res["numpy_reference_a2_minus_jaxdse"] = float(theta[-1, 1] - jd.estimate_batch(
        [rec0], plant, cfg, FAST).a2[0])
    print(f"numpy: {res['numpy_reference_gen_samples_per_s']:.0f} gen-samples/s", flush=True)

    # UKFs
    data = [ukf_inputs(s, plant) for s in sims]
    u_all = np.stack([d[0] for d in data])
    y_all = np.stack([d[1] for d in data])
    x0_all = np.stack([d[2] for d in data])
    a1_true = np.array([float(s.truth.a1) for s in sims])
    ukf_res = {}
    for joint in (False, True):
        name = "joint" if joint else "state"
        ukf_res[f"dynamax_{name}"] = dynamax_entry(sims, plant, data, 64 if args.quick else 1024, joint)
        n_fp = min(n_t, 1000)
        t = time.perf_counter()
        fp = filterpy_ukf(u_all[0], y_all[0], x0_all[0], m, dt, a1_true[0], a2_true[0], joint, n=n_fp)
        fp_rate = n_fp / (time.perf_counter() - t)
        fp_full = fp if n_fp == n_t else filterpy_ukf(u_all[0], y_all[0], x0_all[0], m, dt, a1_true[0],
                                                      a2_true[0], joint)
        fp_entry = {"batch": 1, "gen_samples_per_s": fp_rate, "x2_rmse_rad_s": float(np.sqrt(np.mean(
            (fp_full[n_t // 2:, 1] - x2_true[0, n_t // 2:]) ** 2)))}
        if joint:
            fp_entry["a2_error_percent"] = float(100 * (fp_full[-1, 4] - a2_true[0]) / a2_true[0])
        ukf_res[f"filterpy_{name}"] = fp_entry
        print(name, ukf_res[f"dynamax_{name}"], fp_entry, flush=True)
    res["ukf"] = ukf_res

    # batch identification (jd.identify) on the same recordings, at the joint UKF's batch. Its
    # output is a2 AND the 95 % interval of H, so that XLA cannot drop the interval's work
    # (the bootstrap, the filter spread) as dead code.
    b = 64 if args.quick else 1024
    ident = {}
    for name, ids in (("default", jd.IdentifySettings()),
                      ("sandwich", jd.IdentifySettings(noise_interval="sandwich", spread_scales=())),
                      ("point estimate", jd.IdentifySettings(noise_interval="sandwich", spread_scales=()))):
        ident[name] = identify_entry(sims, plant, b, ids, interval=name != "point estimate")
        ident[name]["interval"] = {"default": f"bootstrap, {ids.bootstrap_draws} draws, filter spread",
                                   "sandwich": "Newey-West sandwich, no filter spread",
                                   "point estimate": "none (a2 only)"}[name]
        print("identify", name, ident[name], flush=True)
    res["identify"] = ident
    res["identify_gen_samples_per_s"] = ident["default"]["gen_samples_per_s"]
    res["identify_a2_error_percent_median"] = ident["default"]["a2_error_percent_median_abs"]
    res["dynamax_ukf_gen_samples_per_s"] = ukf_res["dynamax_state"]["gen_samples_per_s"]
    res["filterpy_ukf_gen_samples_per_s"] = ukf_res["filterpy_state"]["gen_samples_per_s"]

    # gradient cost
    res.update(gradient_cost(sims, plant, cfg, (1, 4) if args.quick else (1, 4, 16)))

    # memory
    if args.keep_memory:
        old = json.loads((HERE / "results.json").read_text())
        res.update({k: v for k, v in old.items() if k.startswith(("peak_rss", "memory_case"))})
    elif not args.quick:
        measure_memory(res)

    if not args.quick and (HERE / "results.json").exists():  # fleet_scaling.py's and dyr_playback.py's own
        old = json.loads((HERE / "results.json").read_text())
        res.update({k: v for k, v in old.items() if k.startswith(OTHER_SCRIPTS)})
    (HERE / ("results_quick.json" if args.quick else "results.json")).write_text(json.dumps(res, indent=2))
    write_table(res, HERE / ("results_quick.md" if args.quick else "results.md"))


def measure_memory(res):
    for case, key, hours in (("1h_x1024", "peak_rss_gib_1h_x1024", 1.0),
                             ("24h", "peak_rss_gib_24h_chunked", 24.0)):
        out = run_memory(case, hours)
        res[key] = out["peak_rss_gib"]
        res[f"memory_case_{case}"] = out
        print(case, out, flush=True)


def write_table(res, path):
    tp = res["throughput_gen_samples_per_s"]
    ref = tp.get("1024")
    u = res["ukf"]
    lines = [f"# Benchmarks ({res['machine']}, {res['devices']} XLA CPU devices, jax {res['jax']})", "",
             f"`python benchmarks/run.py`: {res['samples_per_recording']} samples per recording at "
             f"{res['frame_rate_hz']:.0f} frames/s, float64.", "",
             "| method | batch | gen-samples/s | compile s | jaxdse@1024 / this |", "|---|---|---|---|---|"]
    for b, v in tp.items():
        lines.append(f"| jaxdse full pipeline, fast | {b} | {v:,.0f} | {res['compile_s'][b]:.1f} | |")

    def rel(v):
        return f"{ref / v:,.1f}x" if ref else ""

    lines.append(f"| NumPy loop (observer only) | 1 | {res['numpy_reference_gen_samples_per_s']:,.0f} | | "
                 f"{rel(res['numpy_reference_gen_samples_per_s'])} |")
    for k, v in u.items():
        lines.append(f"| {k.replace('_', ' UKF ')} | {v['batch']} | {v['gen_samples_per_s']:,.0f} | "
                     f"{v.get('compile_s', 0):.1f} | {rel(v['gen_samples_per_s'])} |")
    for k, v in res.get("identify", {}).items():
        what = v["interval"]
        lines.append(f"| jaxdse identify ({k}: {what}) | {v['batch']} | {v['gen_samples_per_s']:,.0f} | "
                     f"{v['compile_s']:.1f} | {rel(v['gen_samples_per_s'])} |")
    lines += ["", "| accuracy | x2 RMSE rad/s (2nd half) | a2 error % |", "|---|---|---|"]
    a = res["jaxdse_accuracy"]
    lines.append(f"| jaxdse fast | {a['fast (Heun, 1 step/sample)']['x2_rmse_rad_s_median']:.4f} | "
                 f"{a['fast (Heun, 1 step/sample)']['a2_error_percent_median_abs']:.2f} (median abs, 8 rec.) |")  # noqa: E501
    lines.append(f"| jaxdse adaptive | | {a['adaptive (Tsit5)']['a2_error_percent_median_abs']:.2f} |")
    for k, v in res.get("identify", {}).items():
        lines.append(f"| jaxdse identify ({k}) | | {v['a2_error_percent_median_abs']:.3f} (median abs) |")
    for k, v in u.items():
        x2 = v.get("x2_rmse_rad_s_median", v.get("x2_rmse_rad_s"))
        a2 = v.get("a2_error_percent_median_abs", v.get("a2_error_percent"))
        lines.append(f"| {k.replace('_', ' UKF ')} | {x2:.4f} | {'' if a2 is None else f'{a2:.2f}'} |")
    lines += ["", "- value-and-grad / forward of the tuning loss, 4 recordings: "
              f"{res['grad_over_forward']:.2f} ({res['grad_mode']} mode, what `jd.tune` uses there); "
              f"reverse mode {res['grad_over_forward_reverse']:.2f}", "",
              "| recordings | forward pass s | value-and-grad / forward, fwd mode | bwd mode |",
              "|---|---|---|---|"]
    lines += [f"| {n} | {g['forward_s']:.4f} | {g['fwd_over_forward']:.2f} | {g['bwd_over_forward']:.2f} |"
              for n, g in res["grad_by_recordings"].items()]
    lines.append("")
    for key, case in (("peak_rss_gib_1h_x1024", "1h_x1024"), ("peak_rss_gib_24h_chunked", "24h")):
        if key in res:
            base = res[f"memory_case_{case}"].get("baseline_rss_gib")
            lines.append(f"- {key}: {res[key]:.2f} GiB (process peak, VmHWM"
                         + ("" if base is None else f"; {base:.2f} GiB after importing JAX") + ")")
    day = res.get("memory_case_24h", {})
    if "a2_max_error_percent_after_1h" in day:
        lines.append(f"- 24 h recording: a2 {day['a2']:.3f} (truth {day['a2_true']:.3f}), largest a2_hat "
                     f"error after the first hour {day['a2_max_error_percent_after_1h']:.2f} %, "
                     f"converged {day['converged']}")
    path.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
