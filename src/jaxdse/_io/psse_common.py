"""What the PSS/E .dyr and .raw readers share: numbers as PSS/E writes them, quoted strings.

Both formats are free format: fields separated by blanks or commas, strings in single (or, in
newer files, double) quotes, ``/`` ending the data of a line (the rest is a comment), ``@!``
lines comments. Numbers may be Fortran-style (``0.5E-01``, ``1.D-2``).
"""

from __future__ import annotations

import re

_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eEdD][+-]?\d+)?$")


def parse_number(token: str) -> float:
    """A PSS/E number: Fortran exponents ``E``/``D`` (``1.D-2``), no NaN/Inf words."""
    if not _NUMBER.match(token):
        raise ValueError(token)
    return float(token.replace("D", "E").replace("d", "e"))


def unquote(token: str) -> str:
    """A field without its quotes (and the blanks inside them); other fields stripped."""
    return token[1:-1].strip() if token[:1] in "'\"" else token.strip()


def is_comment(line: str) -> bool:
    """``@!`` lines (column headers PSS/E writes before sections) are comments anywhere."""
    return line.lstrip().startswith("@!")


__all__ = ["is_comment", "parse_number", "unquote"]
