"""The playback's compiled program can be written to the persistent compilation cache.

XLA programs with host callbacks are never cached; diffrax's checks of ``SaveAt(ts=...)`` are
equinox ``error_if`` host callbacks by default, so every ``jaxdse fleet`` run compiled every
model chain anew (benchmarks/real_case_fleet.py: 13 chains of ACTIVSg2000). The fixed-step
playback saves its steps instead (``SaveAt(steps=True)``, every ``substeps``-th kept), which
has no such check, and equinox's own setting is never touched.
"""

import equinox as eqx
import equinox._errors as eqx_errors
import jax
import jax.numpy as jnp
import numpy as np

from jaxdse._dyr.playback import PlaybackSettings, TerminalSeries, play_back
from jaxdse._dyr.unit import DyrUnit
from jaxdse._models.machines import GENCLS


def _lowered_text():
    unit = DyrUnit(machine=GENCLS(h_s=5.0, d_pu=1.0, x1_pu=0.3))
    t = np.arange(31) / 30.0
    v, i = np.full_like(t, 1.0), np.full_like(t, 0.5)
    series = TerminalSeries(*(jnp.asarray(x) for x in (t, v, np.zeros_like(t), i, np.zeros_like(t))))
    fn = eqx.filter_jit(eqx.filter_vmap(play_back, in_axes=(0, 0, None)))
    stack = lambda *x: jnp.stack([x[0], x[0]])  # noqa: E731
    return fn.lower(jax.tree.map(stack, unit), jax.tree.map(stack, series),
                    PlaybackSettings()).as_text()


def test_playback_program_has_no_host_callback():
    before = eqx_errors.EQX_ON_ERROR
    text = _lowered_text()
    assert "callback" not in text.lower()
    assert eqx_errors.EQX_ON_ERROR == before


def test_playback_result_unchanged_in_steady_state():
    unit = DyrUnit(machine=GENCLS(h_s=5.0, d_pu=1.0, x1_pu=0.3))
    t = np.arange(31) / 30.0
    v0, p, q = 1.01, 0.6, 0.1
    i = np.conj((p + 1j * q) / v0)
    s = TerminalSeries(*(jnp.asarray(x) for x in (t, np.full_like(t, v0), np.zeros_like(t),
                                                  np.full_like(t, i.real), np.full_like(t, i.imag))))
    r = eqx.filter_jit(play_back)(unit, s)
    assert bool(r.ok)
    np.testing.assert_allclose(r.p_pu, p, atol=1e-10)
    np.testing.assert_allclose(r.q_pu, q, atol=1e-10)


def test_condition_number_of_a_failed_identification_is_nan():
    # benchmarks/real_case_fleet.py: a unit whose solve failed (NaN information) crashed
    # `jaxdse fleet` in eigvalsh (LinAlgError) instead of being reported as failed
    from jaxdse._core.identify import condition_number

    assert np.isnan(condition_number(np.full((3, 3), np.nan)))
    assert np.isclose(condition_number(np.diag([1.0, 4.0])), 4.0)
