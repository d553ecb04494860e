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
