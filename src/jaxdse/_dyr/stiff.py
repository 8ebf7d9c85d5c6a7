"""Stiff units: when an explicit step cannot follow a unit's fastest mode, and the implicit solver
that can, without LAPACK inside the vmapped program.

A unit's modes are the eigenvalues of the Jacobian of its vector field at its initial state. The
Jacobian comes out of the compiled (vmapped) program as plain arithmetic (``jax.jacfwd``); the
eigenvalues are computed here, on the host, with NumPy (``../shared/STYLE.md`` points 15 and
22: batched LAPACK custom calls inside vmapped programs are the likely cause of the XLA CPU
thread-pool deadlocks seen in this project).

Kvaerno5's Newton iterations solve a small linear system per stage; diffrax's default goes through
lineax's LU, i.e. LAPACK ``getrf``/``trsm`` custom calls, batched under vmap. :func:`kvaerno5`
is the same solver with :class:`PlainLU`: Gaussian elimination with partial pivoting written
as plain array arithmetic in loops over the (small: a unit has 5-30 states) dimension.
"""

from __future__ import annotations

import math
from typing import Any

import diffrax
import equinox.internal as eqxi
import jax.numpy as jnp
from jax import lax
import lineax as lx
import numpy as np
from lineax._solver.misc import pack_structures, ravel_vector, transpose_packed_structures, unravel_solution

EXPLICIT_LIMIT = 3.3
"""An explicit Runge-Kutta step h follows a real mode lambda only while h |lambda| stays below
about this (Tsit5's and Dormand-Prince's stability region on the negative real axis)."""


def _factor(a):
    """(LU with unit lower triangle packed, row order) of the square matrix ``a`` by Gaussian
    elimination with partial pivoting; plain arithmetic in a loop over the rows (one traced
    step, whatever the size: a program compiles in seconds, not minutes)."""
    rows = jnp.arange(a.shape[0])

    def step(k, carry):
        a, order = carry
        p = jnp.argmax(jnp.where(rows >= k, jnp.abs(a[:, k]), -1.0))
        swap = jnp.where(rows == k, p, jnp.where(rows == p, k, rows))   # exchange rows k and p
        a, order = a[swap], order[swap]
        pivot = a[k, k]
        factor = jnp.where(rows > k, a[:, k] / jnp.where(pivot == 0, 1.0, pivot), 0.0)
        a = a - factor[:, None] * jnp.where(rows[None, :] > k, a[k][None, :], 0.0)
        return jnp.where((rows[None, :] == k) & (rows[:, None] > k), factor[:, None], a), order

    return lax.fori_loop(0, a.shape[0], step, (a, rows))


def _solve(lu, order, b):
    """x with A x = b, from :func:`_factor`'s (lu, order) of A."""
    n = lu.shape[0]
    if n == 0:
        return b
    b = b[order]
    rows = jnp.arange(n)

    def forward(i, y):   # unit lower triangle
        return y.at[i].set(b[i] - jnp.sum(jnp.where(rows < i, lu[i] * y, 0.0)))

    def back(k, x):      # upper triangle, from the last row
        i = n - 1 - k
        return x.at[i].set((y[i] - jnp.sum(jnp.where(rows > i, lu[i] * x, 0.0))) / lu[i, i])

    y = lax.fori_loop(0, n, forward, jnp.zeros_like(b))
    return lax.fori_loop(0, n, back, jnp.zeros_like(b))


class PlainLU(lx.AbstractLinearSolver):
    """lineax's LU solver without LAPACK: :func:`_factor` and :func:`_solve` in plain
    arithmetic (square, nonsingular operators of a few tens of rows)."""

    def init(self, operator, options: dict[str, Any]):
        del options
        if operator.in_size() != operator.out_size():
            raise ValueError("PlainLU needs a square operator")
        matrix = operator.as_matrix()
        return _factor(matrix), matrix, pack_structures(operator), eqxi.Static(False)

    def compute(self, state, vector, options: dict[str, Any]):
        del options
        (lu, order), _, packed, _ = state
        x = _solve(lu, order, ravel_vector(vector, packed))
        return unravel_solution(x, packed), lx.RESULTS.successful, {}

    def transpose(self, state, options: dict[str, Any]):
        _, matrix, packed, transposed = state
        return (_factor(matrix.T), matrix.T, transpose_packed_structures(packed),
                eqxi.Static(not transposed.value)), {}

    def conj(self, state, options: dict[str, Any]):
        _, matrix, packed, transposed = state
        return (_factor(matrix.conj()), matrix.conj(), packed, transposed), {}

    def assume_full_rank(self):
        return True


def kvaerno5() -> diffrax.Kvaerno5:
    """diffrax's Kvaerno5 (implicit, L-stable, 5th order) whose Newton iterations solve with
    :class:`PlainLU` (no LAPACK custom call in the vmapped program)."""
    chord = diffrax.with_stepsize_controller_tols(diffrax.VeryChord)(linear_solver=PlainLU())
    return diffrax.Kvaerno5(root_finder=chord)


def modes(jacobian) -> tuple[float, float]:
    """(largest, smallest) real part [1/s] of the eigenvalues of a unit's Jacobian (host NumPy),
    the zero eigenvalues of states that do not move (bypassed blocks, integrators on a limit,
    references) aside: the largest below 0 says what motion is left decays (its time constant
    -1/largest); the smallest whether an explicit step can follow the fastest mode. NaN where
    the Jacobian is not finite; -inf/inf where every mode is zero."""
    j = np.asarray(jacobian, dtype=float)
    if j.size == 0:
        return -math.inf, math.inf
    if not np.all(np.isfinite(j)):
        return math.nan, math.nan
    ev = np.linalg.eigvals(j)
    moving = np.abs(ev) > 1e-8
    if not np.any(moving):
        return -math.inf, math.inf
    return float(np.max(ev.real[moving])), float(np.min(ev.real[moving]))


def too_stiff(fastest_per_s: float, step_s: float) -> bool:
    """Whether an explicit step of ``step_s`` cannot follow a mode of real part
    ``fastest_per_s`` (:data:`EXPLICIT_LIMIT`)."""
    return math.isfinite(fastest_per_s) and -fastest_per_s * step_s > EXPLICIT_LIMIT


def stiff_note(fastest_per_s: float, step_s: float, explicit: str) -> str:
    """The note of a unit switched to Kvaerno5."""
    return (f"stiff: fastest mode {fastest_per_s:.4g} 1/s at the initial state; {explicit}'s step "
            f"{step_s:.3g} s would need to stay below {EXPLICIT_LIMIT / -fastest_per_s:.3g} s: "
            "integrated with Kvaerno5 (implicit, adaptive)")


__all__ = ["EXPLICIT_LIMIT", "PlainLU", "kvaerno5", "modes", "stiff_note", "too_stiff"]
