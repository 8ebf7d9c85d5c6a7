"""Exported programs (``jaxdse._many.programs``): written once, loaded by a later process, and
the same results as the traced function's."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxdse._many import programs


class Gain(eqx.Module):
    k: jax.Array
    power: int = eqx.field(static=True)


def scaled(m: Gain, x):
    return m.k * x**m.power, jnp.sum(x)


def test_a_program_is_exported_once_and_loaded_after(tmp_path, monkeypatch):
    monkeypatch.setattr(programs, "_folder", lambda: str(tmp_path))
    monkeypatch.setattr(programs, "_LOADED", {})
    x = jnp.linspace(0.0, 1.0, 7)
    first = programs.call("scaled", scaled, Gain(jnp.asarray(2.0), 2), x)
    files = sorted(tmp_path.glob("scaled-*.stablehlo"))
    assert len(files) == 1
    np.testing.assert_array_equal(first[0], 2.0 * x**2)
    # a new process: nothing in memory, the file is read (not traced: a function that fails
    # when traced would not run)
    monkeypatch.setattr(programs, "_LOADED", {})
    again = programs.call("scaled", lambda m, x: 1 / 0, Gain(jnp.asarray(2.0), 2), x)
    np.testing.assert_array_equal(again[0], first[0])
    # another static value or shape is another program
    programs.call("scaled", scaled, Gain(jnp.asarray(2.0), 3), x)
    programs.call("scaled", scaled, Gain(jnp.asarray(2.0), 2), x[:5])
    assert len(list(tmp_path.glob("scaled-*.stablehlo"))) == 3


def test_without_a_cache_folder_the_function_is_traced(monkeypatch):
    monkeypatch.setattr(programs, "_folder", lambda: None)
    out = programs.call("scaled", scaled, Gain(jnp.asarray(3.0), 1), jnp.ones(3))
    np.testing.assert_array_equal(out[0], 3.0 * np.ones(3))
