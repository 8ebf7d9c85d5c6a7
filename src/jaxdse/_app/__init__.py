"""The command-line tool: ``cli`` (argument parsing), ``run`` (jaxdse run/sweep/tune),
``demo`` (built-in data) and ``report`` (summary.json, CSVs, tables, figures)."""
