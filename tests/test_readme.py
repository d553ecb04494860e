"""README.md's and docs/*.md's examples work as written (issue 22, item 5).

* Every ```python block of README.md and docs/*.md runs in a fresh interpreter (this test's
  ``sys.executable``) in a temporary folder and must exit 0.  Where a block as written would run
  a long exploration, :data:`SHORTER` substitutes smaller settings, by exact text: each
  substitution names the document and the text as written, which must occur in one of its blocks
  (a stale substitution fails), and only shortens the exploration or pins ``jobs=1`` (results do
  not depend on the number of jobs).  README's API block asserts that the run's hull, rebuilt,
  gives the run's own figure; a test checks that the assertion stays in it.
* Every ``explore3d ...`` command line of README.md (its shell blocks after the two install
  commands, and its inline code) is run as written when it is cheap (:data:`RUN_AS_WRITTEN`, in a
  temporary folder holding a small run of the cube as ``runs/cube``: the main command with the
  :data:`SMALL_RUN` settings), else parsed by the CLI's own parser and checked as the CLI checks
  its input before any simulation (the objects exist, the run options resolve, a sweep's objects
  and grid parse).  README's ``reconstruct`` + ``evaluate`` lines must give the run's own figure.
  ``python scripts/...`` lines of README run as written.
* Every ``explore3d ...`` line of docs/*.md's shell blocks parses and is checked the same way;
  their ```toml blocks are valid ``--config`` files or sweep grids.
"""
from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").glob("*.md"))

#: Document (relative to the repository) -> (text as written, text run) for its Python blocks.
SHORTER = {
    "README.md": [
        ('ExploreConfig(mode="planar", directions=3, attempts=4)',
         'ExploreConfig(mode="planar", directions=3, attempts=4, jobs=1)'),
    ],
    "docs/user-guide.md": [
        ('ExploreConfig(mode="planar", directions=3, attempts=4)',
         'ExploreConfig(mode="planar", directions=3, attempts=4, jobs=1)'),
        ('cfg = ExploreConfig(points="links")',  # the default 3D run (96 wraps + probes) -> 4 wraps
         'cfg = ExploreConfig(points="links", directions=4, angles=1, probes=None, jobs=1)'),
        ('ExploreConfig(mode="planar", record=True)',  # 3 directions x 4 attempts -> 1 x 1
         'ExploreConfig(mode="planar", directions=1, attempts=1, jobs=1, record=True)'),
    ],
}

#: The small run of the cube standing in for README's main command (``runs/cube``), for the
#: commands that read its files: 8 wraps, no probes, one process, no pictures (about 20 s),
#: recorded into ``runs/cube/rec`` for ``reconstruct --log``.
SMALL_RUN = ["--directions", "8", "--angles", "1", "--probes", "0", "--jobs", "1", "--no-pictures", "-q",
             "--record", "runs/cube/rec"]

#: README command lines run as written (beginning of the line -> why it is cheap); also every
#: line ending in ``--help`` (the parser only).
RUN_AS_WRITTEN = {
    "explore3d objects": "a list",
    "explore3d arm ": "writes a URDF",
    "explore3d reconstruct ": "hulls the small run's points",
    "explore3d evaluate ": "scores the reconstructed mesh",
    "python scripts/explore_cube.py --quick": "8 wraps, about 20 s",
}

BLOCK_TIMEOUT_S = 600  # a hang guard; each block takes well under a minute on 2 loaded cores


# --- reading the documents ------------------------------------------------------------------------

def fenced_blocks(path: Path, lang: str) -> list[str]:
    """The ```lang blocks of ``path`` (fences may be indented, as in a list), dedented."""
    text = path.read_text()
    return [textwrap.dedent(m.group(2)) for m in
            re.finditer(rf"^( *)```{lang}\n(.*?)^\1```", text, flags=re.S | re.M)]


def _command_lines(block: str) -> list[str]:
    return [ln.strip() for ln in block.splitlines() if ln.strip() and not ln.strip().startswith("#")]


def _normalise(cmd: str) -> str | None:
    """``explore3d ...`` / ``python scripts/...`` without a ``.venv/bin/`` prefix and a trailing
    comment; None for other lines (installs, pytest)."""
    words = shlex.split(cmd, comments=True)
    if not words:
        return None
    if words[0] == ".venv/bin/explore3d":
        words[0] = "explore3d"
    if words[0] == "explore3d" or (words[0] == "python" and len(words) > 1 and words[1].startswith("scripts/")):
        return shlex.join(words)
    return None


def readme_commands() -> list[str]:
    """README's command lines: its shell blocks after the two install commands (tests/test_docs.py
    checks those) and its inline code spans that are commands, in order, without duplicates."""
    text = README.read_text()
    blocks = fenced_blocks(README, "bash")[2:]
    lines = [ln for b in blocks for ln in _command_lines(b)]
    lines += [" ".join(m.group(1).split()) for m in re.finditer(r"`((?:explore3d|python scripts/)[^`]*)`", text)]
    out = []
    for ln in lines:
        cmd = _normalise(ln)
        if cmd is not None and cmd not in out:
            out.append(cmd)
    return out


def docs_commands() -> list[tuple[str, str]]:
    """(document, command) for every explore3d line of docs/*.md's shell blocks."""
    out = []
    for path in DOCS:
        for block in fenced_blocks(path, "bash"):
            for ln in _command_lines(block):
                cmd = _normalise(ln)
                if cmd is not None and cmd.startswith("explore3d"):
                    out.append((path.name, cmd))
    return out


def python_blocks() -> list[tuple[str, int, str]]:
    """(document, index, code to run) for every Python block, :data:`SHORTER` applied."""
    out, used = [], set()
    for path in [README, *DOCS]:
        doc = path.relative_to(ROOT).as_posix()
        for i, code in enumerate(fenced_blocks(path, "python")):
            for j, (old, new) in enumerate(SHORTER.get(doc, [])):
                if old in code:
                    code = code.replace(old, new)
                    used.add((doc, j))
            out.append((doc, i, code))
    stale = [(doc, subs[j][0]) for doc, subs in SHORTER.items() for j in range(len(subs)) if (doc, j) not in used]
    assert not stale, f"substitutions whose text is in no block (update SHORTER): {stale}"
    return out


# --- running and checking -------------------------------------------------------------------------

def _run_python(code: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True,
                          timeout=BLOCK_TIMEOUT_S)


def _argv(cmd: str) -> list[str]:
    """The command as this interpreter runs it: ``explore3d`` as ``python -m explore3d``, a script
    by its path in the repository."""
    words = shlex.split(cmd)
    if words[0] == "explore3d":
        return [sys.executable, "-m", "explore3d", *words[1:]]
    return [sys.executable, str(ROOT / words[1]), *words[2:]]


def check_command(cmd: str) -> None:
    """Parse ``cmd`` (an ``explore3d`` line) with the CLI's parser and check its input as the CLI
    does before any simulation: the objects load, a run's options resolve into an ExploreConfig,
    a sweep's objects and grid parse.  AssertionError naming the command otherwise."""
    from explore3d import load_object
    from explore3d.app.cli import build_parser
    from explore3d.app.settings import UsageError, explore_config, resolve_run_options
    from explore3d.app.sweep import parse_grid, resolve_objects

    words = shlex.split(cmd)[1:]
    try:
        args = build_parser().parse_args(words)
    except SystemExit as exc:  # --help, or argparse's own exit
        raise AssertionError(f"{cmd!r} does not parse (exit {exc.code})") from None
    except UsageError as exc:  # the CLI's parser raises this for a usage error
        raise AssertionError(f"{cmd!r} does not parse: {exc}") from None
    try:
        if args.command in ("run", "compare"):
            if args.command == "run" and not (args.config and not Path(args.config).exists()):
                opts = resolve_run_options(args)
                explore_config(opts)
                load_object(opts["object"], scale=opts.get("scale"), size=opts.get("size"))
            elif args.command == "compare":
                load_object(args.object, size=args.size)
        elif args.command == "sweep":
            resolve_objects(args.objects)
            parse_grid(args.grid)
    except (UsageError, ValueError, OSError) as exc:
        raise AssertionError(f"{cmd!r} is refused: {exc}") from None


def _as_written(cmd: str) -> bool:
    return cmd.endswith(" --help") or any(cmd == k.strip() or cmd.startswith(k) for k in RUN_AS_WRITTEN)


# --- the tests ------------------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("doc,index,code", [pytest.param(d, i, c, id=f"{d}#{i + 1}") for d, i, c in python_blocks()])
def test_python_block_runs(doc, index, code, tmp_path):
    r = _run_python(code, tmp_path)
    assert r.returncode == 0, f"{doc}, Python block {index + 1}:\n{code}\n--- stderr:\n{r.stderr[-3000:]}"


def test_readme_api_block_checks_the_run_figure():
    """README's API block rebuilds the run's hull and asserts it gives the run's own figure (the
    old block hulled every candidate point and printed 26.2% against the run's 1.5%)."""
    blocks = [b for b in fenced_blocks(README, "python") if "run(" in b]
    assert blocks, "README has no Python block that runs an exploration"
    for b in blocks:
        assert re.search(r"^assert .*== res\.error\.percent", b, flags=re.M), b


def test_a_failing_block_fails(tmp_path):
    """The runner sees a block that raises (the test can fail)."""
    assert _run_python("raise SystemExit(3)", tmp_path).returncode == 3
    assert _run_python("assert 1.5 == 26.2", tmp_path).returncode != 0


@pytest.mark.slow
def test_readme_commands_work_as_written(tmp_path):
    """The cheap README commands run as written beside a small run of the cube (``runs/cube``);
    ``reconstruct`` then ``evaluate`` give that run's figure; the quick script writes its own folder
    and leaves ``runs/cube`` alone; every other README command parses and passes the CLI's checks."""
    cmds = readme_commands()
    assert any(c.startswith("explore3d run ") for c in cmds) and len(cmds) >= 10, cmds
    small = subprocess.run([sys.executable, "-m", "explore3d", "run", "cube", "--out", "runs/cube", *SMALL_RUN],
                           cwd=tmp_path, capture_output=True, text=True, timeout=BLOCK_TIMEOUT_S)
    assert small.returncode == 0, small.stderr
    report_text = (tmp_path / "runs/cube/report.json").read_text()
    report = json.loads(report_text)
    ran = []
    for cmd in cmds:
        if not _as_written(cmd):
            if cmd.startswith("explore3d"):
                check_command(cmd)
            else:
                assert (ROOT / shlex.split(cmd)[1]).is_file(), cmd
            continue
        r = subprocess.run(_argv(cmd), cwd=tmp_path, capture_output=True, text=True, timeout=BLOCK_TIMEOUT_S)
        assert r.returncode == 0, f"{cmd!r} failed ({r.returncode}):\n{r.stderr[-3000:]}"
        ran.append((cmd, r.stdout))
    names = [c for c, _ in ran]
    assert any(c.startswith("explore3d reconstruct ") and "--free-space" in c for c in names), names
    evaluated = [out for c, out in ran if c.startswith("explore3d evaluate ")]
    assert evaluated, names
    figures = json.loads([ln for ln in evaluated[0].splitlines() if ln.startswith("{")][-1])
    # the STL stores float32 vertices; the uncarved hull differs by about 0.4% of the figure
    assert figures["percent"] == pytest.approx(report["percent_error"], rel=1e-6), (figures, report["percent_error"])
    if any(c.startswith("python scripts/explore_cube.py --quick") for c in names):
        assert (tmp_path / "runs/cube-quick/summary.json").is_file()
        assert (tmp_path / "runs/cube/report.json").read_text() == report_text  # not overwritten


@pytest.mark.parametrize("doc,cmd", docs_commands())
def test_docs_command_parses(doc, cmd, monkeypatch):
    monkeypatch.chdir(ROOT)  # relative paths (objects/nonconvex/...) as from the clone's folder
    check_command(cmd)


def test_check_command_refuses_what_the_cli_refuses():
    """The checker is not blind: an unknown built-in (the old README's ``explore3d run torus``), an
    unknown option and a bad value are refused."""
    for bad in ("explore3d run torus --out runs/torus", "explore3d run cube --out o --wraps 3",
                "explore3d run cube --out o --probes 0 --fingers 3", "explore3d sweep torus --out o",
                "explore3d reconstruct p.ply"):
        with pytest.raises(AssertionError):
            check_command(bad)


@pytest.mark.parametrize("path", [p for p in DOCS if fenced_blocks(p, "toml")], ids=lambda p: p.name)
def test_docs_toml_blocks_are_configs_or_grids(path, tmp_path):
    from explore3d.app.settings import read_toml_config
    from explore3d.app.sweep import read_grid_file

    for i, block in enumerate(fenced_blocks(path, "toml")):
        f = tmp_path / f"block{i}.toml"
        f.write_text(block)
        if re.search(r"^(out|object)\s*=", block, flags=re.M):
            assert read_toml_config(f)
        else:
            assert read_grid_file(f)


# --- figures cite the BENCHMARKS section they come from (issue 43, item 4) ----------------------------

BENCHMARKS = ROOT / "BENCHMARKS.md"
CITE = re.compile(r'BENCHMARKS\.md, "([^"]+)"')
PERCENT = re.compile(r"(\d+\.\d+)(?:-(\d+\.\d+))?%")


def benchmarks_section(title: str) -> str:
    """The text of BENCHMARKS.md's section whose heading contains ``title``, up to the next
    heading of the same or a higher level ("" when none has it)."""
    lines = BENCHMARKS.read_text(encoding="utf-8").splitlines()
    for i, line in enumerate(lines):
        m = re.match(r"^(#+) (.*)", line)
        if m and title in m.group(2):
            level = len(m.group(1))
            end = next((j for j in range(i + 1, len(lines))
                        if (h := re.match(r"^(#+) ", lines[j])) and len(h.group(1)) <= level), len(lines))
            return "\n".join(lines[i:end])
    return ""


def cited_paragraphs(path: Path):
    """(paragraph, [titles]) of ``path``'s paragraphs that cite BENCHMARKS.md sections."""
    for para in re.split(r"\n\s*\n", path.read_text(encoding="utf-8")):
        titles = CITE.findall(" ".join(para.split()))
        if titles:
            yield " ".join(para.split()), titles


@pytest.mark.parametrize("path", [README, ROOT / "docs" / "user-guide.md"], ids=lambda p: p.name)
def test_figures_name_the_benchmarks_section_they_come_from(path):
    """Every BENCHMARKS.md section a paragraph of README.md or the user guide cites exists, and every
    percentage that paragraph gives (a figure or a range) stands in one of the sections it cites."""
    paragraphs = list(cited_paragraphs(path))
    assert paragraphs, f"{path.name} cites no BENCHMARKS.md section"
    for para, titles in paragraphs:
        text = ""
        for t in titles:
            section = benchmarks_section(t)
            assert section, f"{path.name} cites BENCHMARKS.md section {t!r}, which has no heading"
            text += section
        for m in PERCENT.finditer(para):
            for figure in filter(None, m.groups()):
                assert figure in text, (f"{path.name}: {figure}% is not in BENCHMARKS.md {titles}: "
                                        f"...{para[max(0, m.start() - 80):m.end() + 20]}...")


def test_a_figure_not_in_its_section_is_caught(tmp_path, monkeypatch):
    """The check above fails on a paragraph whose figure its cited section does not hold."""
    doc = tmp_path / "doc.md"
    doc.write_text('The cube gives 97.13% (BENCHMARKS.md, "Current figures").\n', encoding="utf-8")
    with pytest.raises(AssertionError, match="97.13"):
        test_figures_name_the_benchmarks_section_they_come_from(doc)
