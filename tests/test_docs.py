"""README's two commands and .ci/run agree (the CI runs exactly the README's test command)."""
import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _readme_commands():
    blocks = re.findall(r"```bash\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    return [b.strip() for b in blocks[:2]]


def test_readme_commands_use_a_virtual_environment():
    run_cmd, test_cmd = _readme_commands()
    for cmd in (run_cmd, test_cmd):
        steps = [s.strip() for s in cmd.split("&&")]
        assert steps[0] == "apt-get update" and "python3-venv" in steps[1]
        assert steps[2] == "python3 -m venv .venv"
        assert steps[3] == '.venv/bin/pip install -c constraints.txt -e ".[all]"'  # the pinned versions
    assert run_cmd.endswith(".venv/bin/explore3d run cube --out runs/cube")
    assert test_cmd.endswith(".venv/bin/python -m pytest -q -n 2")  # both cores (pytest-xdist)


def test_constraints_pin_every_dependency():
    """constraints.txt gives one exact version (==) of every dependency pyproject.toml names."""
    import re

    pins = {}
    for ln in (ROOT / "constraints.txt").read_text().splitlines():
        if ln.strip() and not ln.startswith("#"):
            name, _, version = ln.partition("==")
            assert version and re.fullmatch(r"[0-9][0-9A-Za-z.+!-]*", version), ln
            pins[re.sub(r"[-_.]+", "-", name).lower()] = version
    text = (ROOT / "pyproject.toml").read_text()
    deps = re.findall(r'^\s*"([A-Za-z0-9_.-]+)\s*[><=!~;\[]', text, flags=re.M)
    assert len(deps) > 10
    for dep in deps:
        key = re.sub(r"[-_.]+", "-", dep).lower()
        if key in ("explore3d", "setuptools", "wheel", "open3d", "tomli"):  # self, build-only, other platforms
            continue
        assert key in pins, dep


def test_ci_runs_the_readme_test_command():
    ci = (ROOT / ".ci" / "run").read_text()
    assert "set -euo pipefail" in ci
    lines = [ln.strip() for ln in ci.splitlines() if ln.strip() and not ln.strip().startswith("#")]
    _, test_cmd = _readme_commands()
    steps = [s.strip() for s in test_cmd.split("&&")][2:]  # after the apt-get steps
    pip = lines.index("python3 -m venv .venv")
    assert lines[pip:] == [steps[0], steps[1].replace("pip install", "pip install -q"), steps[2]]
    assert subprocess.run(["bash", "-n", str(ROOT / ".ci" / "run")]).returncode == 0


README_MAX_LINES = 150  # issue 22: README holds what a newcomer needs; the rest is in docs/


def _markdown_files():
    return [ROOT / "README.md", ROOT / "BENCHMARKS.md", *sorted((ROOT / "docs").glob("*.md"))]


def test_readme_is_short():
    n = len((ROOT / "README.md").read_text().splitlines())
    assert n <= README_MAX_LINES, f"README.md has {n} lines (at most {README_MAX_LINES}: move the rest into docs/)"


def test_readme_links_to_docs_that_exist():
    """Every docs/*.md README names exists, and README links to each of the guides."""
    text = (ROOT / "README.md").read_text()
    named = set(re.findall(r"docs/[A-Za-z0-9_.-]+\.md", text))
    assert {"docs/user-guide.md", "docs/robot-interface.md", "docs/files.md", "docs/method.md", "docs/scene.md",
            "docs/architecture.md"} <= named, named
    for rel in named:
        assert (ROOT / rel).is_file(), rel


def test_relative_links_resolve():
    """Every relative Markdown link ``[text](path)`` (and image) of README, BENCHMARKS and docs/
    points at a file of the repository; ``#anchor`` parts name a heading of that file."""
    for md in _markdown_files():
        for target in re.findall(r"\]\(([^)\s]+)\)", md.read_text()):
            if re.match(r"[a-z]+://", target):
                continue
            path, _, anchor = target.partition("#")
            dest = (md.parent / path).resolve() if path else md
            assert dest.exists(), f"{md.name}: link to {target!r}: no such file"
            if anchor and dest.suffix == ".md":
                slugs = {re.sub(r"[^a-z0-9 -]", "", h.lower()).strip().replace(" ", "-")
                         for h in re.findall(r"^#+ (.+)$", dest.read_text(), flags=re.M)}
                assert anchor in slugs, f"{md.name}: link to {target!r}: no such heading"


def test_module_paths_resolve():
    """Every dotted ``explore3d.x.y`` path the documents name is a module or an attribute of one
    (the floors moved every module: issue 22)."""
    import importlib

    bad = []
    for md in _markdown_files():
        text = md.read_text()
        for name in sorted(set(re.findall(r"\bexplore3d(?:\.[A-Za-z_][A-Za-z0-9_]*)+", text))):
            parts = name.split(".")
            for i in range(len(parts), 0, -1):
                try:
                    obj = importlib.import_module(".".join(parts[:i]))
                except ImportError:
                    continue
                try:
                    for attr in parts[i:]:
                        obj = getattr(obj, attr)
                except AttributeError:
                    bad.append(f"{md.name}: {name}")
                break
            else:
                bad.append(f"{md.name}: {name}")
    assert not bad, bad


def test_quoted_benchmarks_sections_exist():
    """Every ``BENCHMARKS.md, "Section"`` / ``BENCHMARKS.md ("Section"`` a document quotes begins a
    heading of BENCHMARKS.md."""
    headings = re.findall(r"^#+ (.+)$", (ROOT / "BENCHMARKS.md").read_text(), flags=re.M)
    for md in _markdown_files():
        for name in re.findall(r'BENCHMARKS\.md\W{1,3}"([^"]+)"', md.read_text()):
            name = " ".join(name.split())  # quoted across a line break
            assert any(h.startswith(name) for h in headings), f"{md.name} quotes BENCHMARKS.md section {name!r}"
