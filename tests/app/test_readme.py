"""README's measured figures are the results files' (pasted by experiments/readme_results.py)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_readme_quotes_the_results_files():
    out = subprocess.run([sys.executable, str(ROOT / "experiments" / "readme_results.py"), "--check"],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
