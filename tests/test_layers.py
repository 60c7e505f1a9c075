"""The flow of the package runs one way, and the README states the code's limits."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from camtraj.usd_shot import MAX_FRAMES

ROOT = Path(__file__).resolve().parents[1]


def _imports(path: Path) -> set[str]:
    """Every module ``path`` imports, at run time or for type checking only."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            found.add(node.module)
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
    return found


def test_the_report_does_not_import_convert() -> None:
    """The report reads what convert computed (camtraj.analysis); it never runs back up the
    flow to convert (issue 14)."""
    files = sorted((ROOT / "camtraj" / "report").glob("*.py"))
    assert files
    for path in files:
        assert "camtraj.convert" not in _imports(path), path
        assert not any(name.startswith("camtraj.convert.") for name in _imports(path)), path
    assert "camtraj.convert" not in _imports(ROOT / "camtraj" / "analysis.py")


def test_the_readme_states_the_frame_cap_of_the_code() -> None:
    text = (ROOT / "README.md").read_text()
    caps = re.findall(r"at most \*\*([\d,]+) frames\*\*", text)
    assert caps, "the README states no frame cap"
    assert {int(c.replace(",", "")) for c in caps} == {MAX_FRAMES}
