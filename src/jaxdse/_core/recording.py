"""A PMU recording as validated arrays: the one input type of the pure pipeline."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._base.fields import as_float
from .mapping import LOCATIONS, Location
from .sequence import positive_sequence


class Recording(eqx.Module):
    """Positive-sequence PMU phasors on a uniform time grid [pu, system base].

    Currents flow from the plant towards the grid. Angles are unwrapped (continuous) and
    measured against a reference rotating at the nominal frequency, as a PMU reports them.
    """

    t_s: Float[Array, " T"] = eqx.field(converter=as_float)
    """Sample times [s], uniform."""
    v_mag_pu: Float[Array, " T"] = eqx.field(converter=as_float)
    """Voltage magnitude [pu]."""
    v_ang_rad: Float[Array, " T"] = eqx.field(converter=as_float)
    """Voltage angle [rad]."""
    i_mag_pu: Float[Array, " T"] = eqx.field(converter=as_float)
    """Current magnitude [pu]."""
    i_ang_rad: Float[Array, " T"] = eqx.field(converter=as_float)
    """Current angle [rad]."""
    f_hz: Float[Array, " T"] | None = eqx.field(default=None)
    """Measured frequency [Hz]; None when the recording has no frequency channel. Samples
    that are NaN take the frequency derived from the voltage angle (``front_end``)."""
    n_samples: Array | None = eqx.field(default=None)
    """Number of valid samples when the arrays are padded at the end (see
    :func:`jaxdse.stack_recordings`); None: all samples are valid."""
    location: Location = eqx.field(static=True, default="substation")
    """Where the PMU sits: "substation", "hv" (transformer HV side) or "terminal"."""

    def __check_init__(self):
        if self.location not in LOCATIONS:
            raise ValueError(f"Recording.location must be one of {LOCATIONS}, got {self.location!r}")
        shape = np.shape(self.t_s)
        for name in ("v_mag_pu", "v_ang_rad", "i_mag_pu", "i_ang_rad", "f_hz"):
            value = getattr(self, name)
            if value is not None and np.shape(value)[-1:] != shape[-1:]:
                raise ValueError(f"Recording.{name} has shape {np.shape(value)}, t_s has {shape}")
        if shape[-1] < 8:
            raise ValueError(f"Recording needs at least 8 samples, got {shape[-1]}")

    @property
    def v(self):
        return self.v_mag_pu * jnp.exp(1j * self.v_ang_rad)

    @property
    def i(self):
        return self.i_mag_pu * jnp.exp(1j * self.i_ang_rad)


def pad_end(x, size: int, *, time: bool = False) -> np.ndarray:
    """Extend ``x`` (host array, time first) to ``size`` samples: a time axis continues its
    uniform step, any other signal repeats its last sample (padding that masks then ignore)."""
    x = np.asarray(x)
    extra = size - x.shape[0]
    if extra <= 0:
        return x
    tail = x[-1] + (x[-1] - x[-2]) * np.arange(1, extra + 1) if time else np.repeat(x[-1:], extra, axis=0)
    return np.concatenate([x, tail])


def recording_from_three_phase(t_s, v_abc, i_abc, f_hz=None, location: Location = "substation"):
    """Recording from complex three-phase phasors ``[T, 3]``: keeps the positive sequence."""
    v1 = positive_sequence(jnp.asarray(v_abc))
    i1 = positive_sequence(jnp.asarray(i_abc))
    return Recording(
        t_s=t_s,
        v_mag_pu=jnp.abs(v1),
        v_ang_rad=jnp.unwrap(jnp.angle(v1)),
        i_mag_pu=jnp.abs(i1),
        i_ang_rad=jnp.unwrap(jnp.angle(i1)),
        f_hz=f_hz,
        location=location,
    )
