"""The package's floors (docs/architecture.md): the import-linter contracts of pyproject.toml hold
(floors import only downwards; the strategy, feeling and everything below never import pybullet or
the simulated world; no import circles), and every import made inside a function says why: an
optional extra, or a module kept out of ``explore3d --help``'s start-up."""
from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "explore3d"
REASONS = ("optional extra", "start-up")


def _lint_imports() -> str | None:
    exe = shutil.which("lint-imports") or str(Path(sys.executable).parent / "lint-imports")
    return exe if Path(exe).exists() else None


def test_import_contracts_hold():
    exe = _lint_imports()
    if exe is None:
        pytest.fail("lint-imports (import-linter) is not installed: pip install -c constraints.txt -e '.[test]'")
    r = subprocess.run([exe, "--no-cache"], cwd=PACKAGE.parent, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    assert "0 broken" in r.stdout and "3 kept" in r.stdout, r.stdout[-2000:]


def _function_imports(tree):
    """(import node, the statements of its contiguous block of imports) for every import inside a function."""
    for f in ast.walk(tree):
        if not isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for node in ast.walk(f):
            for field in ("body", "orelse", "finalbody", "handlers"):
                body = getattr(node, field, None)
                if not isinstance(body, list):
                    continue
                block = []
                for s in body + [None]:
                    if isinstance(s, (ast.Import, ast.ImportFrom)):
                        block.append(s)
                        continue
                    for imp in block:
                        yield imp, block
                    block = []


def unexplained_function_imports() -> list[str]:
    """``path:line: statement`` of every import inside a function whose block of imports carries no
    comment (on its lines or the line above) naming one of :data:`REASONS`."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        lines = path.read_text().splitlines()
        tree = ast.parse("\n".join(lines))
        seen = set()
        for imp, block in _function_imports(tree):
            if id(imp) in seen:
                continue
            seen.add(id(imp))
            lo, hi = block[0].lineno - 1, block[-1].end_lineno
            text = " ".join(lines[max(lo - 1, 0):hi])
            comments = " ".join(t.split("#", 1)[1] for t in lines[max(lo - 1, 0):hi] if "#" in t)
            if not any(r in comments for r in REASONS):
                out.append(f"{path.relative_to(PACKAGE.parent)}:{imp.lineno}: {ast.unparse(imp)}")
    return out


def test_imports_inside_functions_say_why():
    bad = unexplained_function_imports()
    assert not bad, "imports inside functions must say why (an optional extra, or kept out of --help's start-up):\n" + "\n".join(bad)


def test_checker_finds_an_unexplained_import(tmp_path, monkeypatch):
    """The checker is not blind: a function-level import without a reason is reported, one with a
    reason is not."""
    pkg = tmp_path / "explore3d"
    pkg.mkdir()
    (pkg / "m.py").write_text("def f():\n    import json\n    return json\n\n\ndef g():\n"
                              "    import trimesh  # kept out of explore3d --help's start-up\n    return trimesh\n")
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", pkg)
    assert unexplained_function_imports() == ["explore3d/m.py:2: import json"]
