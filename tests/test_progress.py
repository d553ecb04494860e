"""The progress display (explore3d.app.progress): one bar whose total is the planned maximum from the
start, never at 100% before the command ends, log lines above it, a line per phase without a terminal."""
import io
import re

import pytest

from explore3d.app.cli import main
from explore3d.app.progress import Progress

BAR = re.compile(r"^(?P<desc>.*?): +(?P<pct>\d+)%\|")
AT_MOST = re.compile(r"\((?P<done>\d+) of at most (?P<total>\d+) wraps\)")


class Terminal(io.StringIO):
    """What a terminal receives (tqdm draws a bar only where ``isatty`` is true)."""

    def isatty(self):
        return True


def frames(text: str) -> list[str]:
    """The bar's frames and the log lines, in order: tqdm redraws after a carriage return."""
    return [f for chunk in text.split("\r") for f in chunk.split("\n") if f.strip()]


@pytest.fixture(scope="module")
def tiny_arm(tmp_path_factory):
    from explore3d import ArmSpec, write_arm_urdf

    return write_arm_urdf(ArmSpec(name="small16", n_links=16, link_length=0.02),
                          tmp_path_factory.mktemp("arm") / "small16.urdf")


def test_bar_of_a_run_with_probes_never_shows_100_before_the_end(tmp_path, monkeypatch, tiny_arm):
    """A small 3D run with a round of probes (its wraps' total is only known as a maximum) on a
    terminal, with -v: the percentage only grows, reaches 100% only in the last frame, after the
    writing step; the wraps' maximum is stated from the first wrap and never changes; the run's wraps
    stay within it; every log line stands on its own line, never on the bar."""
    import json

    term = Terminal()
    monkeypatch.setattr("sys.stderr", term)
    out = tmp_path / "o"
    code = main(["run", "cube", "--out", str(out), "--arm", str(tiny_arm), "--mode", "3d", "--directions", "24",
                 "--offsets", "1", "--angles", "1", "--attempts", "1", "--probes", "1", "--fingers", "2",
                 "--pokes", "2", "--format", "off", "--no-pictures", "-v"])
    monkeypatch.undo()
    assert code == 0, term.getvalue()[-2000:]
    shown = frames(term.getvalue())
    bars = [(f, BAR.match(f)) for f in shown if BAR.match(f)]
    pct = [int(m["pct"]) for _, m in bars]
    assert pct == sorted(pct), pct  # never goes back
    assert pct[-1] == 100 and all(p < 100 for p in pct[:-1]), pct
    phases = [m["desc"].split(" (")[0] for _, m in bars]
    assert phases.index("writing") < len(phases) - 1  # the last frame follows the writing step
    assert {"planned wraps", "probe round 1 of at most 1", "reconstructing", "scoring", "writing"} <= set(phases)
    totals = {int(AT_MOST.search(f)["total"]) for f, _ in bars if AT_MOST.search(f)}
    assert len(totals) == 1, totals  # the planned maximum, from the first wrap to the last
    report = json.loads((out / "report.json").read_text())
    assert 24 < report["n_wraps"] <= totals.pop()
    logs = [f for f in shown if "INFO" in f]
    assert logs and not any("%|" in f for f in logs)  # a log record never lands on the bar


def test_without_a_terminal_one_line_per_phase(tmp_path, monkeypatch, tiny_arm):
    """stderr to a file: no bar, no carriage return, each phase named once, in order."""
    err = io.StringIO()
    monkeypatch.setattr("sys.stderr", err)
    code = main(["run", "cube", "--out", str(tmp_path / "o"), "--arm", str(tiny_arm), "--mode", "planar",
                 "--directions", "3", "--format", "off", "--no-pictures"])
    monkeypatch.undo()
    text = err.getvalue()
    assert code == 0, text
    assert "\r" not in text and "%|" not in text
    lines = text.splitlines()
    assert all(line.startswith("explore3d: ") for line in lines), lines
    names = [line.removeprefix("explore3d: ").split(" (")[0] for line in lines]
    assert names[-4:] == ["planned wraps", "reconstructing", "scoring", "writing"], names
    assert len(names) == len(set(names))


def test_work_beyond_the_maximum_grows_the_total_but_never_fills_the_bar():
    """A persistent world repeats a wrap after which the object moved: the wraps outgrow their
    stated maximum; the bar's total grows with them and still only finish() shows 100%."""
    term = Terminal()
    with Progress(("writing",), stream=term) as p:
        p(0, 3, "planned wraps")
        for done in (1, 2, 3, 4, 5):  # two repeats
            p(done, 3 + max(0, done - 3), "planned wraps")
        p.step("writing")
        before = term.getvalue()
        p.finish()
    pct = [int(m["pct"]) for f in frames(before) if (m := BAR.match(f))]
    assert pct and max(pct) < 100 and pct == sorted(pct)
    assert "5 of at most 5 wraps" in before
    assert any(int(m["pct"]) == 100 for f in frames(term.getvalue()) if (m := BAR.match(f)))


def test_quiet_shows_nothing_and_an_unknown_step_is_refused():
    term = Terminal()
    with Progress(("writing",), stream=term, enabled=False) as p:
        p(1, 2, "planned wraps")
        p.step("writing")
        p.finish()
    assert term.getvalue() == ""
    with Progress(("writing",), stream=io.StringIO()) as p, pytest.raises(ValueError, match="writing"):
        p.step("scoring")
