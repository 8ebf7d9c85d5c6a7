"""File readers at the edge (never inside jit): CSV, COMTRADE and MATLAB .mat -> a column table.

Each reader turns one file into a :class:`Table`: named columns of raw values, in file units
and file row order. Units, time handling and the positive sequence are applied afterwards by
``measurement``. Every user mistake raises :class:`InputError`, a one-line message that
names the file, the column or key, and the row.

CSV exports come in many layouts. The reader handles, and reports in ``Table.notes``: a
UTF-8 byte-order mark (Excel "CSV UTF-8"), Windows line ends, a latin-1 encoding, the
separator (sniffed from the header when not given: comma, semicolon, tab, pipe or
whitespace), a decimal comma (with a semicolon, tab or whitespace separator), a units row
under the header, metadata lines before it (``skip_rows``, or lines starting with ``#``),
unnamed empty columns (trailing separators), and the usual words for a missing value. The
numbers are parsed by pandas' C reader (24 h at 50 frames/s, 4.3 million rows, in a few s).
"""

from __future__ import annotations

import csv
import functools
import gzip
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import InputError

FORMATS = ("csv", "comtrade", "mat")
NA_WORDS = ("", "nan", "NaN", "NAN", "na", "NA", "n/a", "N/A", "null", "NULL", "None", "-", "--",
            "#N/A", "#VALUE!", "inf", "-inf")
"""Cells read as a missing value (NaN) in every CSV; ``CsvOptions.na_values`` adds more."""
SEPARATORS = {",": "comma", ";": "semicolon", "\t": "tab", "|": "pipe"}


@dataclass(frozen=True)
class CsvOptions:
    """How to read a CSV/text export (the CSV keys of [measurement]). None: detect it."""

    delimiter: str | None = None
    """Field separator: ",", ";", "\\t", "|" or "whitespace"; None sniffs it from the header."""
    quotechar: str = '"'
    decimal: str | None = None
    """"." or ","; None: "," when the cells look like "50,01" with a non-comma separator."""
    na_values: tuple[str, ...] = ()
    """Words that mean a missing value, beside ``NA_WORDS``."""
    skip_rows: int = 0
    """Lines to skip before the header (metadata); lines starting with "#" are skipped anyway."""
    units_row: bool | None = None
    """A row of units under the header; None: detected (a non-numeric first row whose numeric
    columns parse from the next row on)."""


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
    notes: dict = field(default_factory=dict)
    """What the reader detected and handled (separator, BOM, decimal comma, units row, ...)."""
    unreadable: dict = field(default_factory=dict)
    """Column name -> (file, message, row) of its first cell that is not a number (the column
    holds NaN there): an :class:`InputError` only when the config maps the column
    (:meth:`column`), so that a text column nobody asked for (a PMU STAT column of words, a
    station name) is ignored."""

    def column(self, name: str | int, role: str) -> np.ndarray:
        """The column ``name`` (or 0-based position), or an InputError naming ``role``."""
        names = list(self.columns)
        if isinstance(name, int) and not isinstance(name, bool):
            if not 0 <= name < len(names):
                raise InputError(self.source, f"there is no column number {name} "
                                 f"(the file has {len(names)})", column=role)
            self._readable(names[name])
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
        self._readable(name)
        return self.columns[name]

    def _readable(self, name: str) -> None:
        if name in self.unreadable:
            path, message, row = self.unreadable[name]
            raise InputError(path, message, column=name.split("/", 1)[-1] if path != self.source
                             else name, row=row)


def load_table(paths, fmt: str | None = None, *, csv_options: CsvOptions = CsvOptions(),
               time_column: str | int | None = None) -> Table:
    """Read one file, or several files with the same time axis, into one :class:`Table`.

    With several files, each column is named ``"<file stem>/<column>"``.

    Arguments:
        paths: a path or a list of paths.
        fmt: "csv", "comtrade" or "mat"; None infers it from the extension.
        csv_options: separator, decimal mark, missing-value words, rows to skip, units row.
        time_column: the time column, kept as text when it is not numeric (timestamps).
    """
    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
    tables = [_load_cached(p, _mtime(p), fmt, csv_options, time_column) for p in paths]
    if len(tables) == 1:
        return tables[0]
    columns, units, unreadable = {}, {}, {}
    n = len(next(iter(tables[0].columns.values())))
    for p, tab in zip(paths, tables):
        m = len(next(iter(tab.columns.values())))
        if m != n:
            raise InputError(p, f"has {m} rows but {paths[0]} has {n}; files must share one time axis")
        for name, values in tab.columns.items():
            columns[f"{p.stem}/{name}"] = values
            if name in tab.units:
                units[f"{p.stem}/{name}"] = tab.units[name]
            if name in tab.unreadable:
                unreadable[f"{p.stem}/{name}"] = tab.unreadable[name]
    ambiguous = frozenset(f"{p.stem}/{a}" for p, tab in zip(paths, tables) for a in tab.ambiguous)
    return Table(source=" + ".join(map(str, paths)), columns=columns, units=units,
                 first_row=tables[0].first_row, ambiguous=ambiguous, notes=tables[0].notes,
                 unreadable=unreadable)


def _mtime(path: Path):
    return path.stat().st_mtime_ns if path.exists() else None


@functools.lru_cache(maxsize=8)
def _load_cached(path: Path, mtime, fmt, csv_options, time_column) -> Table:
    """One file read once per run, however many generators share it (``mtime`` keys changes)."""
    return _load_one(path, fmt, csv_options, time_column)


def _load_one(path: Path, fmt, csv_options: CsvOptions, time_column) -> Table:
    if fmt is None:
        fmt = _format_from_suffix(path)
    if fmt not in FORMATS:
        raise InputError(path, f"unknown format {fmt!r}; use one of {', '.join(FORMATS)}",
                         key="measurement.format")
    if not path.exists():
        raise InputError(path, "file does not exist")
    if fmt == "csv":
        return _read_csv(path, csv_options, time_column)
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

def _read_csv(path: Path, opt: CsvOptions, time_column) -> Table:
    gz = path.suffix.lower() == ".gz"
    with (gzip.open if gz else open)(path, "rb") as fh:
        head = fh.read(1 << 16)
    notes = {}
    encoding = "utf-8-sig"
    if head.startswith(b"\xef\xbb\xbf"):
        head, notes["byte_order_mark"] = head[3:], "stripped (UTF-8 BOM)"
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError as err:
        if err.start < len(head) - 4:  # not just a character cut at the end of the head
            encoding, notes["encoding"] = "latin-1", "latin-1 (not UTF-8)"
        text = head.decode(encoding.replace("-sig", ""), errors="replace")
    lines = text.split("\n")
    if len(head) == 1 << 16:
        lines = lines[:-1]  # the last line of the head may be cut
    if "\r\n" in text:
        notes["line_ends"] = "CRLF (Windows)"
    # Metadata lines before the header: skip_rows, then blank and "#" comment lines.
    k = opt.skip_rows
    while k < len(lines) and (not lines[k].strip() or lines[k].lstrip().startswith("#")):
        k += 1
    if k >= len(lines):
        raise InputError(path, "the file is empty" if not text.strip() else "no header line found")
    if k:
        notes["skipped_lines"] = f"{k} line(s) before the header (skip_rows = {opt.skip_rows}, " \
            "then blank and '#' lines)"
    sep = opt.delimiter or _sniff_separator(lines[k:k + 20])
    if opt.delimiter is None:
        notes["separator"] = f"{SEPARATORS.get(sep, repr(sep))} (detected)"
    header, ambiguous = _dedupe([h.strip() for h in _split_line(lines[k], sep, opt.quotechar)])
    body = k + 1  # 0-based line index of the first line after the header
    while body < len(lines) and not lines[body].strip():
        body += 1
    rows = [_split_line(lines[j], sep, opt.quotechar) for j in range(body, min(body + 2, len(lines)))
            if lines[j].strip()]
    if not rows:
        raise InputError(path, "the file has a header but no data rows")
    decimal = opt.decimal or _detect_decimal(sep, rows[-1])
    if opt.decimal is None and decimal == ",":
        notes["decimal"] = "comma (detected)"
    if decimal == "," and sep == ",":
        raise InputError(path, "a decimal comma needs another separator than the comma; set "
                         "measurement.delimiter", key="measurement.decimal")
    na = set(NA_WORDS) | set(opt.na_values)
    units_row = opt.units_row
    if units_row is None:
        units_row = len(rows) == 2 and _looks_like_units(rows[0], rows[1], na, decimal)
        if units_row:
            notes["units_row"] = "detected under the header and read as units"
    units = {}
    if units_row:
        units = {h: u.strip() for h, u in zip(header, rows[0]) if u.strip()}
        body += 1
    columns, unreadable = _parse_body(path, body, header, sep, opt.quotechar, decimal, na, time_column,
                                      encoding)
    empty = [h for h, raw in zip(header, _split_line(lines[k], sep, opt.quotechar))
             if not raw.strip() and columns[h].dtype.kind == "f" and np.all(np.isnan(columns[h]))
             and h not in unreadable]
    if empty:
        notes["empty_columns"] = f"{len(empty)} unnamed column(s) without values ignored " \
            "(separators at the ends of the lines)"
        columns = {h: c for h, c in columns.items() if h not in empty}
    return Table(source=str(path), columns=columns, units=units, first_row=body + 1,
                 ambiguous=ambiguous, notes=notes, unreadable=unreadable)


def _split_line(line: str, sep: str, quotechar: str) -> list[str]:
    if sep == "whitespace":
        return next(csv.reader([line.strip()], delimiter=" ", quotechar=quotechar, skipinitialspace=True))
    return next(csv.reader([line.rstrip("\r\n")], delimiter=sep, quotechar=quotechar))


def _sniff_separator(lines: list[str]) -> str:
    """The separator that splits the header and the next lines into the same, largest count."""
    sample = [ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")][:10]
    best, best_count = None, 1
    for sep in (",", ";", "\t", "|"):
        counts = {len(_split_line(ln, sep, '"')) for ln in sample}
        if len(counts) == 1 and (n := counts.pop()) > best_count:
            best, best_count = sep, n
    if best is None:
        counts = {len(ln.split()) for ln in sample}
        if len(counts) == 1 and counts.pop() > 1:
            return "whitespace"
        return ","
    return best


_DECIMAL_COMMA = re.compile(r"^\s*[-+]?\d+,\d+([eE][-+]?\d+)?\s*$")


def _detect_decimal(sep: str, row: list[str]) -> str:
    if sep == ",":
        return "."
    return "," if any(_DECIMAL_COMMA.match(c) for c in row) else "."


def _number(cell: str, na: set, decimal: str):
    cell = cell.strip()
    if cell in na:
        return np.nan
    try:
        return float(cell.replace(",", ".") if decimal == "," else cell)
    except ValueError:
        return None


def _looks_like_units(first: list[str], second: list[str], na: set, decimal: str) -> bool:
    """A first data row that is not numeric in columns whose next row is numeric."""
    if not first or not second or len(first) != len(second):
        return False
    flips = [_number(a, na, decimal) is None and _number(b, na, decimal) is not None
             for a, b in zip(first, second)]
    return sum(flips) >= max(2, len(first) // 2)


def _parse_body(path, skip: int, header, sep, quotechar, decimal, na, time_column, encoding):
    """The data lines after the first ``skip`` lines, one array per column (pandas' C reader),
    and the error of each column with a cell that is not a number (see ``Table.unreadable``).
    Hexadecimal words (``0x8000``, C37.118 STAT as some exports write it) are read as integers."""
    import pandas as pd

    first_row = skip + 1

    time_name = header[time_column] if isinstance(time_column, int) and 0 <= time_column < len(header) \
        else time_column
    kwargs = dict(header=None, names=header, index_col=False, quotechar=quotechar, decimal=decimal,
                  na_values=sorted(na), keep_default_na=False, skip_blank_lines=True, skiprows=skip,
                  engine="c", skipinitialspace=True, sep=r"\s+" if sep == "whitespace" else sep,
                  encoding=encoding, encoding_errors="replace", comment=None)
    try:
        frame = pd.read_csv(path, **kwargs)
    except pd.errors.ParserError as err:
        m = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", str(err))
        if m:
            hint = ""
            if int(m.group(1)) < int(m.group(3)) and int(m.group(2)) <= first_row + 20:
                hint = ": lines before the header? set measurement.skip_rows"
            raise InputError(path, f"has {m.group(3)} fields but the header has {m.group(1)}{hint}",
                             row=int(m.group(2))) from None
        raise InputError(path, f"cannot be read as CSV ({str(err).splitlines()[0]})") from None
    columns, unreadable = {}, {}
    for name in header:
        col = frame[name]
        if name == time_name and col.dtype.kind not in "fiu":
            text = col.astype(object)
            numeric = pd.to_numeric(text.str.replace(",", ".") if decimal == "," else text,
                                    errors="coerce")
            if numeric.notna().sum() == text.notna().sum():  # plain numbers after all
                columns[name] = numeric.to_numpy(dtype=float)
            else:
                columns[name] = text.fillna("").to_numpy(dtype=str)
            continue
        if col.dtype.kind in "fiu":
            columns[name] = col.to_numpy(dtype=float)
            continue
        values = pd.to_numeric(col, errors="coerce")
        bad = values.isna() & col.notna()
        if bad.any() and _all_hex(col[bad]):
            values = values.where(~bad, col[bad].map(lambda c: float(int(str(c).strip(), 16))))
            bad = values.isna() & col.notna()
        if bad.any():
            k = int(np.flatnonzero(bad.to_numpy())[0])
            cell = str(col.iloc[k])
            hint = ""
            if sep == "," and re.fullmatch(r"[-+]?\d+;\S*", cell):
                hint = "; the separator may be ';' (set measurement.delimiter)"
            elif decimal == "." and _DECIMAL_COMMA.match(cell):
                hint = "; a decimal comma? set measurement.decimal = \",\""
            else:
                hint = "; add the word to measurement.na_values if it marks a missing value"
            unreadable[name] = (str(path), f"value {cell!r} is not a number{hint}", first_row + k)
        columns[name] = values.to_numpy(dtype=float)
    return columns, unreadable


_HEX = re.compile(r"\s*0[xX][0-9a-fA-F]+\s*")


def _all_hex(cells) -> bool:
    """Every cell a hexadecimal word such as ``0x8000``."""
    return all(isinstance(c, str) and _HEX.fullmatch(c) for c in cells)


def _dedupe(header: list[str]) -> tuple[list[str], frozenset]:
    """Repeated header names become "name#2", "name#3"; the bare name is then ambiguous."""
    seen: dict[str, int] = {}
    out = []
    for h in header:
        seen[h] = seen.get(h, 0) + 1
        out.append(h if seen[h] == 1 else f"{h}#{seen[h]}")
    return out, frozenset(h for h, n in seen.items() if n > 1)


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
