"""File readers at the edge (never inside jit): CSV, COMTRADE and MATLAB .mat -> a column table.

Each reader turns one file into a :class:`Table`: named columns of raw values, in file units
and file row order. Units, time handling and the positive sequence are applied afterwards by
:mod:`._measurement`. Every user mistake raises :class:`InputError`, a one-line message that
names the file, the column or key, and the row.
"""

from __future__ import annotations

import csv
import functools
import gzip
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import InputError

FORMATS = ("csv", "comtrade", "mat")


@dataclass
class Table:
    """Raw columns of one recording, in file units and file row order."""

    source: str
    columns: dict[str, np.ndarray]
    """Column name -> values: float64, or str for a time column with timestamps."""
    units: dict[str, str] = field(default_factory=dict)
    """Column name -> unit written in the file, where the format carries one."""
    first_row: int = 1
    """Row number (1-based, as a user counts rows in the file) of the first data row."""
    ambiguous: frozenset = frozenset()
    """Names the header repeats; the repeats are named "name#2", ... and the bare name is refused."""

    def column(self, name: str | int, role: str) -> np.ndarray:
        """The column ``name`` (or 0-based position), or an InputError naming ``role``."""
        names = list(self.columns)
        if isinstance(name, int) and not isinstance(name, bool):
            if not 0 <= name < len(names):
                raise InputError(self.source, f"there is no column number {name} "
                                 f"(the file has {len(names)})", column=role)
            return self.columns[names[name]]
        if name in self.ambiguous:
            raise InputError(self.source, f"the header repeats {name!r}; name one of "
                             f"{name!r}, '{name}#2', ... by position", column=name)
        if name not in self.columns:
            near = [n for n in names if str(name).lower() in n.lower()][:3]
            hint = f"; did you mean {', '.join(map(repr, near))}?" if near else \
                f"; the file has {len(names)} columns, e.g. {', '.join(map(repr, names[:4]))}"
            raise InputError(self.source, f"no column named {name!r} for {role}{hint}",
                             column=name)
        return self.columns[name]


def load_table(paths, fmt: str | None = None, *, delimiter: str = ",", quotechar: str = '"',
               time_column: str | int | None = None) -> Table:
    """Read one file, or several files with the same time axis, into one :class:`Table`.

    With several files, each column is named ``"<file stem>/<column>"``.

    Arguments:
        paths: a path or a list of paths.
        fmt: "csv", "comtrade" or "mat"; None infers it from the extension.
        delimiter: CSV field separator; "whitespace" for space-aligned text.
        quotechar: CSV quote character.
        time_column: the time column, kept as text when it is not numeric (ISO timestamps).
    """
    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
    tables = [_load_cached(p, _mtime(p), fmt, delimiter, quotechar, time_column) for p in paths]
    if len(tables) == 1:
        return tables[0]
    columns, units = {}, {}
    n = len(next(iter(tables[0].columns.values())))
    for p, tab in zip(paths, tables):
        m = len(next(iter(tab.columns.values())))
        if m != n:
            raise InputError(p, f"has {m} rows but {paths[0]} has {n}; files must share one time axis")
        for name, values in tab.columns.items():
            columns[f"{p.stem}/{name}"] = values
            if name in tab.units:
                units[f"{p.stem}/{name}"] = tab.units[name]
    ambiguous = frozenset(f"{p.stem}/{a}" for p, tab in zip(paths, tables) for a in tab.ambiguous)
    return Table(source=" + ".join(map(str, paths)), columns=columns, units=units,
                 first_row=tables[0].first_row, ambiguous=ambiguous)


def _mtime(path: Path):
    return path.stat().st_mtime_ns if path.exists() else None


@functools.lru_cache(maxsize=8)
def _load_cached(path: Path, mtime, fmt, delimiter, quotechar, time_column) -> Table:
    """One file read once per run, however many generators share it (``mtime`` keys changes)."""
    return _load_one(path, fmt, delimiter, quotechar, time_column)


def _load_one(path: Path, fmt, delimiter, quotechar, time_column) -> Table:
    if fmt is None:
        fmt = _format_from_suffix(path)
    if fmt not in FORMATS:
        raise InputError(path, f"unknown format {fmt!r}; use one of {', '.join(FORMATS)}",
                         key="measurement.format")
    if not path.exists():
        raise InputError(path, "file does not exist")
    if fmt == "csv":
        return _read_csv(path, delimiter, quotechar, time_column)
    if fmt == "comtrade":
        return _read_comtrade(path)
    return _read_mat(path)


def _format_from_suffix(path: Path) -> str:
    suffix = "".join(path.suffixes[-2:]).lower() if path.suffix.lower() == ".gz" else path.suffix.lower()
    if suffix in (".csv", ".txt", ".csv.gz", ".txt.gz", ".tsv"):
        return "csv"
    if suffix in (".cfg", ".dat", ".cff"):
        return "comtrade"
    if suffix == ".mat":
        return "mat"
    raise InputError(path, f"cannot tell the format from the extension {suffix!r}; "
                     "set measurement.format", key="measurement.format")


# --- CSV ------------------------------------------------------------------------------------

def _read_csv(path: Path, delimiter: str, quotechar: str, time_column) -> Table:
    opener = gzip.open if path.suffix.lower() == ".gz" else open
    with opener(path, "rt", newline="") as fh:
        lines = [ln for ln in fh if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise InputError(path, "the file is empty")
    if delimiter == "whitespace":
        reader = csv.reader((ln.strip() for ln in lines), delimiter=" ", quotechar=quotechar,
                            skipinitialspace=True)
    else:
        reader = csv.reader(lines, delimiter=delimiter, quotechar=quotechar, skipinitialspace=True)
    rows = list(reader)
    header = [h.strip() for h in rows[0]]
    body = rows[1:]
    if not body:
        raise InputError(path, "the file has a header but no data rows")
    header, ambiguous = _dedupe(header)
    for k, r in enumerate(body):
        if len(r) != len(header):
            raise InputError(path, f"has {len(r)} fields but the header has {len(header)}",
                             row=k + 2)
    cols = list(zip(*body))
    time_name = header[time_column] if isinstance(time_column, int) else time_column
    columns = {}
    for name, raw in zip(header, cols):
        values = _parse_numbers(raw)
        if values is None:
            if name == time_name:
                columns[name] = np.array([s.strip() for s in raw], dtype=str)
                continue
            bad = next(k for k, s in enumerate(raw) if _to_float(s) is None)
            raise InputError(path, f"value {raw[bad]!r} is not a number", column=name, row=bad + 2)
        columns[name] = values
    return Table(source=str(path), columns=columns, first_row=2, ambiguous=ambiguous)


def _dedupe(header: list[str]) -> tuple[list[str], frozenset]:
    """Repeated header names become "name#2", "name#3"; the bare name is then ambiguous."""
    seen: dict[str, int] = {}
    out = []
    for h in header:
        seen[h] = seen.get(h, 0) + 1
        out.append(h if seen[h] == 1 else f"{h}#{seen[h]}")
    return out, frozenset(h for h, n in seen.items() if n > 1)


_NAN_WORDS = {"", "nan", "NaN", "NAN", "na", "NA", "null", "NULL", "-", "#N/A"}


def _to_float(s: str):
    s = s.strip()
    if s in _NAN_WORDS:
        return np.nan
    try:
        return float(s)
    except ValueError:
        return None


def _parse_numbers(raw) -> np.ndarray | None:
    try:  # fast path: every field is a plain number
        return np.array(raw, dtype=float)
    except ValueError:
        values = [_to_float(s) for s in raw]
        if any(v is None for v in values):
            return None
        return np.array(values, dtype=float)


# --- COMTRADE (IEEE C37.111) ----------------------------------------------------------------

def _read_comtrade(path: Path) -> Table:
    """ASCII, BINARY, BINARY32 and FLOAT32 data, 1991/1999/2013 revisions, via ``comtrade``."""
    import comtrade

    cfg = path.with_suffix(".cfg") if path.suffix.lower() == ".dat" else path
    if cfg.suffix.lower() == ".cfg":
        dat = _sibling(cfg, ".dat")
        if dat is None:
            raise InputError(cfg, "no .dat file with the same name beside the .cfg")
        if not cfg.exists():
            raise InputError(cfg, "file does not exist")
        args = (str(cfg), str(dat))
    else:
        args = (str(cfg),)
    rec = comtrade.Comtrade(use_numpy_arrays=True, use_double_precision=True,
                            ignore_warnings=True)
    try:
        rec.load(*args)
    except (ValueError, IndexError, TypeError, comtrade.ComtradeError) as err:
        raise InputError(path, f"not a readable COMTRADE file ({err})") from None
    columns = {"time": np.asarray(rec.time, dtype=float)}
    units = {"time": "s"}
    for ch, values in zip(rec.cfg.analog_channels, rec.analog):
        name = ch.name.strip()
        if name in columns:
            raise InputError(path, "two analog channels share this name", column=name)
        columns[name] = np.asarray(values, dtype=float)
        # The reader returns primary values when the cfg says P, secondary when S; we want primary.
        if str(ch.pors).strip().upper() == "S" and ch.secondary:
            columns[name] = columns[name] * ch.primary / ch.secondary
        units[name] = ch.uu.strip()
    return Table(source=str(path), columns=columns, units=units, first_row=1)


def _sibling(path: Path, suffix: str) -> Path | None:
    for s in (suffix, suffix.upper()):
        p = path.with_suffix(s)
        if p.exists():
            return p
    return None


# --- MATLAB .mat ----------------------------------------------------------------------------

def _read_mat(path: Path) -> Table:
    """A v5 .mat file in one of two layouts.

    * A numeric matrix with a header cell array of the same width (an Excel/historian export,
      e.g. ``num`` + ``txt``): each column is named by its first two header rows,
      ``"<label>/<quantity>"`` (e.g. ``"Sub:6:Gen:Gen1/VM"``); a third header row is its unit.
    * One vector per channel: each column is named by its variable.
    """
    import scipy.io

    try:
        data = scipy.io.loadmat(str(path), squeeze_me=False)
    except (ValueError, NotImplementedError, OSError) as err:
        raise InputError(path, f"not a readable MATLAB v5 file ({err}); v7.3 files are HDF5, "
                         "save with -v7") from None
    data = {k: v for k, v in data.items() if not k.startswith("__")}
    matrices = {k: v for k, v in data.items()
                if isinstance(v, np.ndarray) and v.ndim == 2 and v.dtype.kind in "fiu" and min(v.shape) > 1}
    cells = {k: v for k, v in data.items() if isinstance(v, np.ndarray) and v.dtype == object}
    for mk, mat in matrices.items():
        for ck, cell in cells.items():
            if cell.ndim == 2 and cell.shape[1] == mat.shape[1]:
                return _mat_header_table(path, mat, cell)
    columns = {k: np.asarray(v, dtype=float).ravel() for k, v in data.items()
               if isinstance(v, np.ndarray) and v.dtype.kind in "fiu" and min(v.shape) == 1}
    if not columns:
        raise InputError(path, "no numeric matrix with a header, and no channel vectors")
    lengths = {len(v) for v in columns.values()}
    if len(lengths) > 1:
        longest = max(lengths)
        columns = {k: v for k, v in columns.items() if len(v) == longest}
    return Table(source=str(path), columns=columns, first_row=1)


def _cell_text(x) -> str:
    if isinstance(x, np.ndarray):
        return str(x.ravel()[0]).strip() if x.size else ""
    return str(x).strip()


def _mat_header_table(path: Path, mat: np.ndarray, cell: np.ndarray) -> Table:
    head = [[_cell_text(cell[r, c]) for c in range(cell.shape[1])] for r in range(min(3, cell.shape[0]))]
    columns, units = {}, {}
    for c in range(mat.shape[1]):
        parts = [head[r][c] for r in range(min(2, len(head))) if head[r][c]]
        name = "/".join(parts) or f"column{c}"
        if name in columns:
            name = f"{name}#{c}"
        columns[name] = np.asarray(mat[:, c], dtype=float)
        if len(head) > 2 and head[2][c]:
            units[name] = head[2][c]
    return Table(source=str(path), columns=columns, units=units, first_row=1)
