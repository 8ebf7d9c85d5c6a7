"""Which REGCV1 constants the recordings of ``generate.py`` identify: the Cramer-Rao 95 %
half-widths (noise only, at the true values; ``jd.rank``) of M, D, xs and the controller
constants from the noisy line trip alone and from the three events together (noise as
``run.py`` adds it). Writes rank.json.

    python experiments/andes_gfm/rank.py
"""

import json
import sys
import zlib
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

import jaxdse as jd  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
import run as bench  # noqa: E402

FIELDS = (("m_s", "M"), ("d_pu", "D"), ("xs_pu", "xs"), ("kpvd", "Kpvd"), ("kivd", "Kivd"),
          ("kpvq", "Kpvq"), ("kivq", "Kivq"), ("kpid", "KpId"), ("kiid", "KiId"), ("t_c_s", "Tc"))


def main():
    meta = json.loads((bench.HERE / "truth.json").read_text())
    unit = jd.GfmUnit(jd.gfm_from_andes(meta["model"], meta["constants"]))
    specs = [jd.ParameterSpec("converter", f, label, 1e-4, 1e3) for f, label in FIELDS]
    series = []
    for event in bench.EVENTS:
        t, v, i, f = bench.read(event, meta["tag"])
        v, i, f = bench.noisy(t, v, i, f, seed=zlib.crc32(f"gfm/{event}".encode()))
        series.append(jd.TerminalSeries(jnp.asarray(t), jnp.abs(v), jnp.unwrap(jnp.angle(v)),
                                        jnp.real(i), jnp.imag(i)))
    out = {}
    for name, chosen in (("line_trip", series[:1]), ("three_events", series)):
        rk = jd.rank(unit, specs, jd.stack_events(chosen))
        out[name] = {label: {"relative_ci95_percent": float(100 * r), "variance_inflation": float(v)}
                     for label, r, v in zip(rk.labels, rk.relative_ci, rk.variance_inflation)}
        for label, r in out[name].items():
            print(f"[gfm rank] {name:12s} {label:5s} +-{r['relative_ci95_percent']:.2f} % "
                  f"(VIF {r['variance_inflation']:.1f})", file=sys.stderr)
    (bench.HERE / "rank.json").write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
