"""Gradient-based tuning of the observer (lambda, c, K, gamma, k) through the whole pipeline.

The loss (:func:`tuning_loss`) has three normalised parts, averaged over the recordings:

* x2: the I&I observer's x2_hat against the measured x2 after a burn-in (mean squared error
  over the mean square of x2_meas);
* playback: the playback's P_t and x2 against the measurements (each over its variance);
* parameter: where the truth is known (synthetic data), with e = (a2_hat(t) - a2)/a2 and
  o(t) = 1 - exp(-(e(t)/band)^2 / 2) a smooth indicator of being outside the band: the time
  averages of e^2 and of o, plus a soft last exit time, the 8-norm over the recording of
  (t/T) o(t). The loss is small only if a2_hat enters the band early and stays: convergence
  time is a *last* exit, which a plain average of o barely sees.

Positive parameters are tuned in log space through one pair of transforms
(:func:`to_log`, :func:`from_log`), bounded smoothly to a factor ``max_factor`` of the start
so that the explicit fixed-step integration stays stable. optimistix's BFGS minimises. The
gradient is taken in one of two modes (``autodiff``):

* ``"bwd"``, reverse mode: back through the checkpointed time loop (``_integrate``: each
  block of samples, and each step in it, is recomputed in the backward pass, so memory grows
  with the number of blocks). Its cost does not grow with the number of parameters.
* ``"fwd"``, forward mode (:func:`forward_mode`): one pass that carries one tangent per
  tuned parameter. Nothing is stored for a backward pass; its cost grows with the number of
  parameters times the batch. For a few recordings it is the cheaper one.

``"auto"`` picks forward mode up to ``FORWARD_MODE_MAX_RECORDINGS`` training recordings.
Value-and-grad over the forward pass (``python benchmarks/run.py``, 2 CPU cores, 9
parameters, 60 s recordings): 1, 4 and 16 recordings took 2.1, 3.0 and 4.9 in forward mode,
against 4.7, 4.9 and 4.5 in reverse mode.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._core.drem import ObserverConfig
from .._core.estimate import estimate
from .._core.plant import Plant
from .._core.recording import Recording
from .._core.settings import Settings
from .._core.tuning import AUTODIFF_MODES, TUNABLE, LossWeights
from .batch import batch_size, stack, stack_recordings

FORWARD_MODE_MAX_RECORDINGS = 8
"""``autodiff="auto"`` uses forward mode up to this many training recordings."""

TUNE_SETTINGS = Settings.fast()


def to_log(config: ObserverConfig, start: ObserverConfig | None = None, names: Sequence[str] = TUNABLE,
           max_factor: float = 10.0) -> jax.Array:
    """The unconstrained coordinates u of ``config`` around ``start`` (default: itself, u = 0):
    the inverse of :func:`from_log`, u = L artanh(ln(p / p_start) / L), L = ln(max_factor).
    Each parameter must lie within ``max_factor`` of its start."""
    start = config if start is None else start
    span = jnp.log(max_factor)
    ratio = jnp.stack([jnp.log(getattr(config, n) / getattr(start, n)) for n in names])
    return span * jnp.arctanh(ratio / span)


def from_log(u, start: ObserverConfig, names: Sequence[str] = TUNABLE,
             max_factor: float = 10.0) -> ObserverConfig:
    """p = p_start * exp(L tanh(u / L)), L = ln(max_factor): log space, smoothly bounded."""
    span = jnp.log(max_factor)
    scale = jnp.exp(span * jnp.tanh(u / span))
    values = [getattr(start, n) * scale[k] for k, n in enumerate(names)]
    return eqx.tree_at(lambda c: [getattr(c, n) for n in names], start, values)


def tuning_loss(config: ObserverConfig, recordings: Recording, plant: Plant,
                settings: Settings = TUNE_SETTINGS, a2_true=None,
                weights: LossWeights = LossWeights()) -> jax.Array:
    """Differentiable loss of ``config`` over a stacked batch of recordings (leading axis).

    ``a2_true`` [B] (or None) enables the parameter part. ``plant`` is one plant shared by
    every recording, or a stacked batch (:func:`jaxdse.stack`) with one plant per recording.
    """
    settings = dataclasses.replace(settings, keep="trajectories")
    plant_axis = None if batch_size(plant) is None else 0

    def one(rec, plant, a2):
        est = estimate(rec, plant, config, settings)
        n = rec.t_s.shape[0] if rec.n_samples is None else rec.n_samples
        valid = jnp.arange(rec.t_s.shape[0]) < n
        after = valid & (est.time_s >= weights.burn_in_s)

        def nmse(sim, meas, mask):
            mean = jnp.sum(jnp.where(mask, meas, 0.0)) / jnp.sum(mask)
            var = jnp.sum(jnp.where(mask, (meas - mean) ** 2, 0.0)) / jnp.sum(mask)
            return jnp.sum(jnp.where(mask, (sim - meas) ** 2, 0.0)) / jnp.sum(mask) / var

        tr = est.trajectories
        loss = weights.x2 * nmse(tr.x2_hat_rad_s, tr.x2_meas_rad_s, after)
        if settings.playback:
            loss += weights.playback * 0.5 * (nmse(tr.playback.p_t_pu, tr.p_t_pu, valid)
                                              + nmse(tr.playback.x2_rad_s, tr.x2_meas_rad_s, valid))
        if a2 is not None:
            rel2 = ((est.a2_hat - a2) / a2) ** 2
            outside = 1.0 - jnp.exp(-0.5 * rel2 / weights.band**2)
            late = est.time_s / est.time_s[n - 1] * outside
            last_exit = (jnp.sum(jnp.where(valid, late**8, 0.0)) / n + 1e-30) ** (1 / 8)
            loss += weights.parameter * (jnp.sum(jnp.where(valid, rel2 + outside, 0.0)) / n + last_exit)
        return loss

    return jnp.mean(jax.vmap(one, in_axes=(0, plant_axis, 0 if a2_true is not None else None))(
        recordings, plant, a2_true))


def resolve_autodiff(autodiff: str, n_recordings: int) -> str:
    """"fwd" or "bwd": ``autodiff`` itself, or for "auto" the cheaper one for that many recordings."""
    if autodiff not in AUTODIFF_MODES:
        raise ValueError(f"autodiff must be one of {AUTODIFF_MODES}, got {autodiff!r}")
    if autodiff != "auto":
        return autodiff
    return "fwd" if n_recordings <= FORWARD_MODE_MAX_RECORDINGS else "bwd"


def settings_for(settings: Settings, mode: str) -> Settings:
    """``settings`` able to take gradients in ``mode``: adaptive steps in forward mode need
    diffrax's forward-mode adjoint (the default one, recursive checkpointing, is reverse only)."""
    if mode != "fwd":
        return settings
    return dataclasses.replace(settings, **{
        k: dataclasses.replace(getattr(settings, k), forward_mode=True)
        for k in ("observer_integrator", "playback_integrator") if getattr(settings, k).adaptive})


def forward_mode(fn: Callable[[jax.Array], jax.Array]) -> Callable[[jax.Array], jax.Array]:
    """``fn`` (vector -> scalar) whose derivative JAX takes in forward mode.

    The JVP rule returns the value and the whole gradient from ``jax.jacfwd`` (one pass
    carrying one tangent per element of the input), so ``jax.grad``, ``jax.value_and_grad``
    and optimistix's ``jax.linearize`` all get the gradient from that single forward pass.
    """

    @jax.custom_jvp
    def wrapped(u):
        return fn(u)

    @wrapped.defjvp
    def _jvp(primals, tangents):
        (u,), (du,) = primals, tangents
        grad, value = jax.jacfwd(lambda v: (fn(v),) * 2, has_aux=True)(u)
        return value, jnp.dot(grad, du)

    return wrapped


class TuneResult(eqx.Module):
    """Tuned configuration and the losses before and after, on training and held-out data."""

    config: ObserverConfig
    """The best configuration on the training recordings."""
    recommended: ObserverConfig
    """``config`` if it improved the held-out loss (the training loss without held-out
    recordings), else the start: a tuning that does not generalise is not recommended."""
    improved: bool
    loss_start: float
    loss_tuned: float
    heldout_loss_start: float | None
    heldout_loss_tuned: float | None
    steps: int
    history: tuple
    """Training loss after each optimiser step."""


def tune(recordings: Sequence[Recording], plant: Plant | Sequence[Plant],
         start: ObserverConfig = ObserverConfig(), a2_true: Sequence[float] | None = None, *,
         heldout: Sequence[Recording] = (), heldout_a2_true: Sequence[float] | None = None,
         heldout_plant: Plant | Sequence[Plant] | None = None, names: Sequence[str] = TUNABLE,
         weights: LossWeights = LossWeights(), settings: Settings = TUNE_SETTINGS,
         max_steps: int = 40, max_factor: float = 10.0, rtol: float = 1e-4, atol: float = 1e-6,
         autodiff: str = "auto", progress: Callable[[int, float], None] | None = None) -> TuneResult:
    """Minimise :func:`tuning_loss` over ``names`` with optimistix BFGS, from ``start``.

    Arguments:
        recordings: training recordings (any lengths; padded and masked).
        plant: one plant for every recording, or one per recording (vmapped).
        a2_true: known a2 per training recording (synthetic data), or None.
        heldout, heldout_a2_true, heldout_plant: cross-validation recordings, scored before
            and after (their plant(s): ``plant`` when it is a single one).
        autodiff: "fwd" (forward mode), "bwd" (reverse mode through the checkpointed time
            loop) or "auto" (forward mode up to ``FORWARD_MODE_MAX_RECORDINGS`` recordings);
            see the module docstring. Both give the same gradient to round-off.
        progress: called with (step, training loss) after each optimiser step.
    """
    autodiff = resolve_autodiff(autodiff, len(recordings))
    settings = settings_for(settings, autodiff)
    names = tuple(names)
    train = stack_recordings(list(recordings))
    if isinstance(plant, list | tuple):
        plant = stack(list(plant))
    a2 = None if a2_true is None else jnp.asarray(a2_true, dtype=float)

    data = (train, a2)  # passed as arguments: closed over, XLA would constant-fold the front end

    def objective(u, data):  # (value, aux), as optimistix solvers take it
        def loss(v):
            return tuning_loss(from_log(v, start, names, max_factor), data[0], plant, settings, data[1],
                               weights)

        return (forward_mode(loss) if autodiff == "fwd" else loss)(u), None

    solver = optx.BestSoFarMinimiser(optx.BFGS(rtol=rtol, atol=atol))
    u = to_log(start, names=names, max_factor=max_factor)
    f_struct = jax.ShapeDtypeStruct((), u.dtype)
    state = solver.init(objective, u, data, {}, f_struct, None, frozenset())
    step = eqx.filter_jit(lambda u, s, d: solver.step(objective, u, d, {}, s, frozenset()))
    terminate = eqx.filter_jit(lambda u, s, d: solver.terminate(objective, u, d, {}, s, frozenset()))
    history, taken = [], 0
    for taken in range(1, max_steps + 1):
        u, state, _ = step(u, state, data)
        history.append(float(state.best_loss))
        if progress is not None:
            progress(taken, history[-1])
        if bool(terminate(u, state, data)[0]):
            break
    best = from_log(state.best_y, start, names, max_factor)
    loss = eqx.filter_jit(tuning_loss)
    held = stack_recordings(list(heldout)) if heldout else None
    held_a2 = None if heldout_a2_true is None else jnp.asarray(heldout_a2_true, dtype=float)
    if heldout_plant is None:
        if batch_size(plant) is not None and held is not None:
            raise ValueError("tune: with one plant per training recording, give heldout_plant")
        heldout_plant = plant
    elif isinstance(heldout_plant, list | tuple):
        heldout_plant = stack(list(heldout_plant))

    def score(cfg, recs, truth, plants):
        return None if recs is None else float(loss(cfg, recs, plants, settings, truth, weights))

    result = dict(loss_start=score(start, train, a2, plant), loss_tuned=score(best, train, a2, plant),
                  heldout_loss_start=score(start, held, held_a2, heldout_plant),
                  heldout_loss_tuned=score(best, held, held_a2, heldout_plant))
    bad = [k for k, v in result.items() if v is not None and not np.isfinite(v)]
    if bad or not np.all(np.isfinite(history)):
        raise FloatingPointError(
            f"the tuning loss is not finite ({', '.join(bad) or 'during the search'}): the "
            "integration failed on these recordings; try integrator = \"adaptive\" or smaller gains")
    if held is not None:
        improved = result["heldout_loss_tuned"] < result["heldout_loss_start"]
    else:
        improved = result["loss_tuned"] < result["loss_start"]
    return TuneResult(config=best, steps=taken, history=tuple(history), improved=bool(improved),
                      recommended=best if improved else start, **result)


def config_values(config: ObserverConfig, names: Sequence[str] = TUNABLE) -> dict[str, float]:
    """The named parameters as plain floats (for TOML/JSON output)."""
    return {n: float(np.asarray(getattr(config, n))) for n in names}
