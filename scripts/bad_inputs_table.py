"""The bad inputs of tests/test_bad_input.py, each run once, as a Markdown table (docs/bad_inputs.md).

    python scripts/bad_inputs_table.py > docs/bad_inputs.md

Each command line runs in-process (explore3d.app.cli.main) in a fresh temporary folder, as the test
runs it; the table gives the exit code and the one line it printed on stderr.
"""
import contextlib
import io
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_bad_input import CASES, _argv  # noqa: E402

from explore3d.app.cli import main  # noqa: E402


def main_table() -> None:
    print("# Bad input on the command line: what each case prints\n")
    print("Made by `python scripts/bad_inputs_table.py > docs/bad_inputs.md` from the cases of "
          "`tests/test_bad_input.py` (which asserts each exit code, one line, no traceback and no file written). "
          "`{name}` is a file the test makes (a mesh with a NaN vertex, an open mesh, a 327,680-face sphere, ...), "
          "`@x` a path in the test's folder.  Exit 2: a usage error; 1: the input cannot be used.  Interrupts, "
          "kills and concurrent sweeps are tested in tests/test_interrupt.py and tests/test_sweep_robust.py.\n")
    print("| command line | exit | stderr |")
    print("|---|---|---|")
    for argv, _, _ in CASES:
        with tempfile.TemporaryDirectory() as d:
            err = io.StringIO()
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                code = main(_argv(Path(d), argv))
            line = " ".join(err.getvalue().split()).replace(d, "DIR").replace("|", "\\|")
        print(f"| `explore3d {' '.join(argv)}` | {code} | {line} |")


if __name__ == "__main__":
    main_table()
