"""Identity check of a refactoring: hashes of the points and the estimate of three runs.

Runs, through the CLI as a user would, the default cube, a planar run and a table-scene run of
the cube, and hashes what each wrote: points.ply (the contact points, bit for bit), the estimate
mesh (estimate.obj) and report.json's error in percent.  Run it before a change to record the
hashes and after it to check them (same machine, same pinned versions: the chain's contact
dynamics amplify rounding, so another machine gives other bits, see BENCHMARKS.md):

    python scripts/studies/identity_hashes.py --record identity.json     # on the commit before
    python scripts/studies/identity_hashes.py --check identity.json      # after: exit 1 if any differs
"""
from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RUNS = {
    "default cube": ["cube"],
    "planar cube": ["cube", "--mode", "planar"],
    "table-scene cube": ["cube", "--scene", "table"],
}


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def run_all(python: str) -> dict:
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, args in RUNS.items():
            folder = Path(tmp) / name.replace(" ", "_")
            t0 = time.perf_counter()
            subprocess.run([python, "-m", "explore3d", "run", *args, "--out", str(folder),
                            "--no-pictures", "-q"], check=True)
            report = json.loads((folder / "report.json").read_text())
            out[name] = {"points_ply_sha256": _sha(folder / "points.ply"),
                         "estimate_obj_sha256": _sha(folder / "estimate.obj"),
                         "error_percent": report["percent_error"],
                         "seconds": round(time.perf_counter() - t0, 1)}
            print(name, out[name], flush=True)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--record", type=Path, help="write the hashes to this JSON file")
    g.add_argument("--check", type=Path, help="compare with the hashes in this JSON file")
    a = p.parse_args(argv)
    got = run_all(sys.executable)
    if a.record:
        a.record.write_text(json.dumps(got, indent=1) + "\n")
        return 0
    want = json.loads(a.check.read_text())
    bad = [f"{name}: {key} {want[name][key]} -> {got[name][key]}"
           for name in RUNS for key in ("points_ply_sha256", "estimate_obj_sha256", "error_percent")
           if want[name][key] != got[name][key]]
    print("\n".join(bad) if bad else "identical: " + ", ".join(RUNS))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
