"""The house: each layer of ``src/jaxdse`` imports only the layers below it, and the
experiments and benchmarks use the public API (``import jaxdse``) or the console script."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "src" / "jaxdse"
BELOW = {
    "_base": set(),
    "_models": {"_base"},
    "_core": {"_base", "_models"},
    "_io": {"_base", "_models", "_core"},
    "_sim": {"_base", "_models", "_core"},
    "_dyr": {"_base", "_models", "_core", "_io", "_sim", "_many"},
    "_many": {"_base", "_models", "_core", "_io", "_sim", "_dyr"},
    "_stream": {"_base", "_models", "_core", "_io", "_sim", "_many", "_dyr"},
    "_app": {"_base", "_models", "_core", "_io", "_sim", "_many", "_dyr", "_stream"},
}
"""What each subpackage may import (besides itself and the top-level ``_version``)."""


def _imports(path: Path, package: str) -> set[str]:
    """The jaxdse subpackages that ``path`` (in ``package``) imports."""
    depth = len(path.relative_to(PKG).parts) - 1   # folders below jaxdse/
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            parts = (node.module or "").split(".")
            if node.level > depth:                  # reaches jaxdse/ itself
                names = parts if parts != [""] else [a.name for a in node.names]
                out.add(names[0])
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            mods = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
            out |= {m.split(".")[1] for m in mods if m.startswith("jaxdse.") and m.count(".") >= 1}
    return out - {package, "_version"}


@pytest.mark.parametrize("package", sorted(BELOW))
def test_a_layer_imports_only_the_layers_below(package):
    for path in sorted((PKG / package).rglob("*.py")):
        wrong = _imports(path, package) - BELOW[package]
        assert not wrong, f"{path.relative_to(ROOT)} imports {sorted(wrong)}"


def test_experiments_and_benchmarks_use_the_public_api():
    for folder in ("experiments", "benchmarks"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            text = path.read_text()
            assert "jaxdse._" not in text, f"{path.relative_to(ROOT)} imports a private module"
