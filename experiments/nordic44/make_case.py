"""Write case.toml for `jaxdse check` on Nordic 44, the case that ANDES ships (N44_BC.raw/.dyr).

Run with the Python of a venv that has ANDES installed (the case files are read where ANDES keeps
them, not copied into this repository):

    python3 -m venv /work/andes-venv && /work/andes-venv/bin/pip install andes
    /work/andes-venv/bin/python experiments/nordic44/make_case.py
    .venv/bin/jaxdse check experiments/nordic44/case.toml --out experiments/nordic44/check

ANDES is imported here only to find its cases folder.
"""

from pathlib import Path

import andes

cases = Path(andes.__file__).resolve().parent / "cases" / "nordic44"
raw, dyr = cases / "N44_BC.raw", cases / "N44_BC.dyr"
for f in (raw, dyr):
    if not f.exists():
        raise SystemExit(f"{f} not found: this ANDES ({andes.__version__}) has no Nordic 44 case")
out = Path(__file__).resolve().parent / "case.toml"
out.write_text(f'# written by make_case.py (ANDES {andes.__version__}): Nordic 44 as ANDES ships it\n'
               f'[case]\nraw = "{raw}"\ndyr = "{dyr}"\n')
print(f"wrote {out}")
