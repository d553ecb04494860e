"""README's picture, made again from today's code: the 80 mm cube after 24 wraps.

    python scripts/readme_picture.py [--out docs/img/cube-24-wraps.png]

Runs ``explore3d run cube --directions 24 --angles 1 --probes 0 --jobs 1`` into a temporary folder,
copies its ``overview.png`` (the estimate over the truth in four views, the arm at its last wrap,
the figures) to ``--out`` and prints the caption's figures (volume error, seconds of exploration),
so README's caption can be checked against the picture it shows.
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COMMAND = ["run", "cube", "--directions", "24", "--angles", "1", "--probes", "0", "--jobs", "1", "-q"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "img" / "cube-24-wraps.png")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "cube-24"
        subprocess.run([sys.executable, "-m", "explore3d", *COMMAND, "--out", str(run)], check=True)
        report = json.loads((run / "report.json").read_text())
        args.out.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(run / "overview.png", args.out)
    print(f"{args.out}: explore3d {' '.join(COMMAND[:-1])}: {report['percent_error']:.2f}% volume error, "
          f"{report['timings']['explore_s']:.0f} s of exploration on one core, {report['n_wraps']} wraps")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
