"""At the edge, never inside jit: files -> validated recordings, TOML -> validated runs, arrays -> files.

``readers`` (CSV, COMTRADE, MATLAB -> column tables), ``measurement`` (units, time, gaps,
screening -> :class:`Recording` segments and a data-quality report), ``config`` (TOML),
``export`` (CSV/COMTRADE writers), ``errors`` (:class:`InputError`).
"""
