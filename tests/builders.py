"""Shared builders of the suite's input files: the run-config TOML and the PMU CSV.

Every test that runs ``jaxdse run`` on a file writes its config through :func:`run_toml`, so
the template exists once. Test configs take few bootstrap draws (``TEST_BOOTSTRAP_DRAWS``):
the interval's noise part is then rougher, but every code path is the same.
"""

from __future__ import annotations

from pathlib import Path

import jaxdse as jd

COLS = {"time": "t", "frequency": "f", "v_mag": "VM", "v_ang": "VA", "i_mag": "IM", "i_ang": "IA"}
"""Column names of the CSVs the tests write (``jd.phasor_columns``)."""
TEST_BOOTSTRAP_DRAWS = 4
PAPER = 'plant_defaults = "paper"'


def columns_toml(columns: dict | None = None) -> str:
    """The [measurement.columns] table's body."""
    return "\n".join(f'{k} = "{v}"' if isinstance(v, str) else f"{k} = {v}"
                     for k, v in (columns or COLS).items())


def run_toml(file: str = "pmu.csv", *, top: str = PAPER, extra: str = "", columns: dict | None = None,
             plant: str = "", output: str = "figures = false\ntrajectories = false",
             identify: str = f"bootstrap_draws = {TEST_BOOTSTRAP_DRAWS}", v_base_kv: float = 400.0) -> str:
    """A `jaxdse run` config: one recording ``file`` (kV and A by default), ``extra`` lines in
    [measurement], optional plant sections, [output] and [identify] bodies."""
    return f"""{top}
[measurement]
file = "{file}"
v_base_kv = {v_base_kv}
min_segment_s = 20.0
{extra}
[measurement.columns]
{columns_toml(columns)}
{plant}
[output]
{output}

[identify]
{identify}
"""


def generator_toml(name: str, file: str, a2_reference: float | None = None) -> str:
    """One [[generator]] table with its own recording."""
    ref = "" if a2_reference is None else f"a2_reference = {a2_reference}\n"
    return f'\n[[generator]]\nname = "{name}"\n{ref}[generator.measurement]\nfile = "{file}"\n'


def write_pmu(path: Path, recording: jd.Recording, columns: dict | None = None, **edits) -> dict:
    """Write ``recording`` as a PMU CSV (kV, A, degrees; ``jd.phasor_columns``) and return its columns."""
    spec = jd.MeasurementSpec(file=(), columns=columns or COLS, v_base_kv=400.0)
    cols = jd.phasor_columns(recording, spec)
    cols.update(edits)
    jd.write_csv(path, cols)
    return cols


EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def example_cut(directory: Path, rows: int) -> Path:
    """The shipped example run configuration (``examples/csv_positive_sequence.toml``) on the
    first ``rows`` rows of its CSV, written into ``directory``: the path of its run.toml."""
    lines = (EXAMPLES / "data" / "pmu_positive_sequence.csv").read_text().splitlines()
    (directory / "pmu.csv").write_text("\n".join(lines[: rows + 1]) + "\n")
    text = (EXAMPLES / "csv_positive_sequence.toml").read_text()
    cut = text.replace('file = "data/pmu_positive_sequence.csv"', f'file = "{directory / "pmu.csv"}"')
    assert cut != text
    (directory / "run.toml").write_text(cut)
    return directory / "run.toml"
