"""The one error type of bad user input: a one-line message naming the file, column or key, and row."""

from __future__ import annotations


class InputError(ValueError):
    """A user's input is wrong: a one-line message naming the file, the column or key, the row."""

    def __init__(self, source, message: str, *, column: str | None = None, key: str | None = None,
                 row: int | str | None = None):
        where = [str(source)]
        if column is not None:
            where.append(f"column {column!r}")
        if key is not None:
            where.append(f"key {key!r}")
        if row is not None:
            where.append(f"row {row}")
        super().__init__(", ".join(where) + ": " + message)
