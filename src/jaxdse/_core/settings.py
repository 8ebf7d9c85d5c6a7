"""Static choices of the pipeline and the thresholds of its flags (never differentiated or vmapped)."""

from __future__ import annotations

from typing import Literal

import equinox as eqx

from .integrate import Integrator

KEEP = ("trajectories", "final")


class Settings(eqx.Module):
    """Static choices of the pipeline: integration, windows, what to keep, flag thresholds."""

    observer_integrator: Integrator = Integrator()
    playback_integrator: Integrator = Integrator(rtol=1e-6, atol=1e-9, min_substep=1 / 16)
    """The playbacks' steps: at least 1/16 of a sample, so that a governor valve sliding along
    its limit is played as a fixed-step simulator plays it (:attr:`Integrator.min_substep`)."""
    derivative_half_width: int = eqx.field(static=True, default=5)
    """Half width (samples) of the least-squares derivative used for x2_meas, f and Ef."""
    qss_window_s: float = eqx.field(static=True, default=30.0)
    """Initial window over which T_ref is taken from the quasi-steady state [s]. Its error
    falls as 1/window (the mean of the measured speed over a window is an angle difference
    over its length) and biases a1, a2: on the noisy synthetic recordings (P = 0.45 pu) a 5 s
    window left a2 up to 2.5 % off, 30 s within 0.6 % (experiments/tuning)."""
    convergence_band: float = eqx.field(static=True, default=0.02)
    """a2_hat has converged once it stays within this relative band of the reference [-]."""
    min_hold_s: float = eqx.field(static=True, default=30.0)
    """Without a known reference: a2_hat must stay in the band of its final value this long [s]."""
    min_log_contraction: float = eqx.field(static=True, default=4.0)
    """Excitation needed: int gamma K Delta^2 dt >= this (error shrunk by e^-4 ~ 1/55) [-]."""
    offline_current_pu: float = eqx.field(static=True, default=0.02)
    """Mean terminal current [pu, machine base] below which the generator counts as offline."""
    torque_balance_tolerance: float = eqx.field(static=True, default=0.05)
    """The governor model carries the load when mean(Tm - Te) is within this fraction of
    mean(Te) [-] (else, e.g., a valve limit below the output saturates Tm)."""
    external_tm: bool = eqx.field(static=True, default=False)
    """Use the ``t_m`` argument of :func:`estimate` instead of the governor model."""
    keep: Literal["trajectories", "final"] = eqx.field(static=True, default="trajectories")
    """What the :class:`Estimate` holds, as diffrax's ``SaveAt`` chooses: every trajectory,
    or (``"final"``) final values, flags and scores with a1_hat and a2_hat at the end of each
    block. "final" stores nothing per sample (large sweeps, long recordings); its
    convergence time then has the resolution of one block."""
    playback: bool = eqx.field(static=True, default=True)
    """Run the event playback (its sMAPE scores are NaN when False)."""
    block_samples: int = eqx.field(static=True, default=50)
    """Samples per block of the time loop: checkpointing (gradients) and ``keep="final"``."""

    @classmethod
    def fast(cls, **kwargs) -> Settings:
        """Fixed-step Heun for the observer and the playback (:meth:`Integrator.fast`): the
        throughput choice for sweeps, tuning and fleets. Other fields as keywords."""
        return cls(observer_integrator=Integrator.fast(), playback_integrator=Integrator.fast(), **kwargs)

    def __check_init__(self):
        if self.keep not in KEEP:
            raise ValueError(f"Settings.keep must be one of {KEEP}, got {self.keep!r}")
        if self.block_samples < 1:
            raise ValueError(f"Settings.block_samples must be >= 1, got {self.block_samples}")
