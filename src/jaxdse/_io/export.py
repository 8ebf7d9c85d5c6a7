"""Write recordings as CSV or COMTRADE in a user's units (examples, tests, hand-over to other tools).

The inverse of the readers: :func:`jaxdse.phasor_columns` turns a Recording into columns in the
units of a :class:`MeasurementSpec`; these functions put such columns in a file.
"""

from __future__ import annotations

import gzip
import struct
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

_INT32_MAX = 2**31 - 1


def write_csv(path, columns: dict[str, np.ndarray], time_column: str | None = None,
              start: datetime | None = None, digits: int = 17) -> None:
    """Columns -> CSV (``.gz`` compresses); with ``start`` the time column becomes ISO 8601."""
    names = list(columns)
    data = [np.asarray(columns[n]) for n in names]
    opener = gzip.open if str(path).endswith(".gz") else open
    with opener(path, "wt") as fh:
        fh.write(",".join(names) + "\n")
        for k in range(len(data[0])):
            row = []
            for n, col in zip(names, data):
                if start is not None and n == time_column:
                    row.append((start + timedelta(seconds=float(col[k]))).isoformat())
                else:
                    row.append(f"{col[k]:.{digits}g}")
            fh.write(",".join(row) + "\n")


def write_comtrade(cfg_path, time_s: np.ndarray, channels: dict[str, np.ndarray],
                   units: dict[str, str], *, data_format: str = "BINARY32",
                   frequency_hz: float = 50.0, station: str = "jaxdse",
                   start: datetime = datetime(2024, 1, 1)) -> None:
    """Analog channels -> IEEE C37.111-2013 COMTRADE (.cfg + .dat), ASCII or BINARY32.

    Each channel is stored as int32 with its own gain a and offset b (value = a * int + b), so
    the quantisation error is (max - min) / 2^32 of the channel's range.
    """
    if data_format not in ("ASCII", "BINARY32"):
        raise ValueError("data_format must be ASCII or BINARY32")
    cfg_path = Path(cfg_path)
    t = np.asarray(time_s, dtype=float)
    n = t.size
    names = list(channels)
    ints, lines = [], []
    for k, name in enumerate(names):
        x = np.asarray(channels[name], dtype=float)
        lo, hi = float(np.min(x)), float(np.max(x))
        b = (hi + lo) / 2
        a = float(max(hi - lo, 1e-12 * max(abs(b), 1.0)) / (2 * (_INT32_MAX - 1)))
        ints.append(np.rint((x - b) / a).astype(np.int64))
        lines.append(f"{k + 1},{name},,,{units.get(name, '')},{a!r},{b!r},0,"
                     f"{-_INT32_MAX},{_INT32_MAX},1,1,P")
    rate = float((n - 1) / (t[-1] - t[0]))
    stamp = start.strftime("%d/%m/%Y,%H:%M:%S.%f")
    cfg = [f"{station},jaxdse,2013", f"{len(names)},{len(names)}A,0D", *lines,
           f"{frequency_hz:g}", "1", f"{rate!r},{n}", stamp, stamp, data_format, "1",
           "+00h00,+00h00", "0,0"]
    cfg_path.write_text("\r\n".join(cfg) + "\r\n")
    us = np.rint((t - t[0]) * 1e6).astype(np.int64)
    dat = cfg_path.with_suffix(".dat")
    if data_format == "ASCII":
        with open(dat, "w") as fh:
            for k in range(n):
                fh.write(",".join([str(k + 1), str(us[k])] + [str(c[k]) for c in ints]) + "\r\n")
    else:
        fmt = "<II" + "i" * len(names)
        with open(dat, "wb") as fh:
            for k in range(n):
                fh.write(struct.pack(fmt, k + 1, us[k], *(int(c[k]) for c in ints)))
