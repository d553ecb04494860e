"""Anytime figures (issue 24, item 5): volume error and coverage against wraps and seconds.
EVALUATION ONLY: the truth is read after the run.

    python scripts/anytime.py --objects nonconvex --label default --out DIR/anytime.jsonl
    python scripts/anytime.py --objects bunny --label sweeps --no-probes --out DIR/anytime.jsonl
    python scripts/anytime.py --objects bunny --label floor20 --probe min_distance_m=0.02 --out DIR/anytime.jsonl
    python scripts/anytime.py --objects nonconvex --label pokes24-seed1 --probe pokes=24 --noise-seed 1 --out DIR/anytime.jsonl

Per object (a built-in name, a name of the fixed non-convex set, or the groups ``nonconvex`` and
``concave``) one default 3D run (ideal scene, the README's sensing, the default arm or ``--arm``; ``--probe KEY=VALUE``
overrides a :class:`~explore3d.strategy.active.ProbeConfig` field, ``--no-probes`` turns probes
off), then the estimate the robot would have had after the first ``k`` wraps, for every ``k`` that
ends a round (the straight sweeps, each round of probes) and every ``--every`` wraps: the hulled
contacts of those wraps (:func:`~explore3d.strategy.explore.hulled_contacts`, as the pipeline
selects them), their inverse hull carved by those wraps' swept space, scored against the truth
(volume error %, split into the estimate's excess outside the truth and the truth it misses, both
in % of the true volume; coverage of the true surface within 3 mm by the hulled contacts) with the wall
time at which the k-th wrap ended.  One JSON line per object is appended to ``--out`` (objects
already in it under the same label are skipped).  ``--table`` prints the file's runs as a Markdown
table instead: per object and label, error % / coverage within 3 mm % / wraps / seconds at the end
of the straight sweeps and of each round.

    python scripts/anytime.py --table --out DIR/anytime.jsonl
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

GROUPS = {"concave": ("l_block", "u_channel", "star_prism")}


def _value(text: str):
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {"None": None, "True": True, "False": False}.get(text, text)


def prefix_score(ex, truth, centre, radius, k: int, seed: int = 0) -> dict:
    """The estimate from the first ``k`` wraps of ``ex`` scored against ``truth``."""
    import numpy as np

    from explore3d.core.defaults import DEFAULT_A
    from explore3d.geometry.metrics import shape_error
    from explore3d.reconstruction.estimators import single_centre
    from explore3d.strategy.explore import hulled_contacts
    from explore3d.world.skin import surface_coverage

    cs = ex.contacts.select(ex.contacts.wrap < k)
    cs = hulled_contacts(cs, ex.config, centre, radius, ex.poses, ex.table_z)
    used = cs.select(cs.used)
    firsts = [np.asarray(p.T_world_base) for p in ex.poses[:k]]
    swept = [s for s in ex.swept if any(np.allclose(s.T_world_base, T) for T in firsts)]
    try:
        est = single_centre(used.points, used.wrap, centre, radius, swept, a=DEFAULT_A)
        e = shape_error(est, truth, seed=seed)
        err, excess, missing = (e.percent, 100 * (e.estimate_size - e.intersection_size) / e.true_size,
                                100 * (e.true_size - e.intersection_size) / e.true_size)
    except ValueError:
        err = excess = missing = float("nan")
    c3, _ = surface_coverage(truth, used.points, seed=seed) if len(used.points) else (0.0, 0.0)
    return {"wraps": k, "percent_error": round(float(err), 3), "excess_percent": round(float(excess), 3),
            "missing_percent": round(float(missing), 3), "coverage_3mm": round(float(c3), 4),
            "hulled_contacts": int(len(used.points))}


def one(name: str, label: str, probe: dict, no_probes: bool, every: int, jobs: int, arm: str = "default",
        noise_seed: int | None = None) -> dict:
    from explore3d import load_object
    from explore3d.app.pipeline import run
    from explore3d.strategy.active import ProbeConfig
    from explore3d.strategy.explore import ExploreConfig
    from nonconvex_set import NONCONVEX_SET, load

    mesh = load(name) if name in NONCONVEX_SET else load_object(name)
    probes = None if no_probes else dataclasses.replace(ProbeConfig(), **probe)
    config = ExploreConfig(jobs=jobs, probes=probes)
    if noise_seed is not None:
        config = dataclasses.replace(config, sensors=dataclasses.replace(config.sensors, seed=noise_seed))
    ends: list[float] = []
    t0 = time.perf_counter()

    def progress(done, total):
        while len(ends) < done:
            ends.append(time.perf_counter() - t0)

    res = run(mesh, arm, config, progress=progress)
    ex = res.exploration
    n = ex.n_wraps
    bounds, k = [], n - sum(r["wraps"] for r in ex.probe_rounds)
    bounds.append(k)
    for r in ex.probe_rounds:
        k += r["wraps"]
        bounds.append(k)
    ks = sorted(set(bounds) | set(range(every, n, every)) | {n})
    curve = []
    for k in ks:
        row = prefix_score(ex, res.truth, res.centre, res.radius, k)
        row["wall_s"] = round(ends[k - 1], 1) if k - 1 < len(ends) else None
        row["round_end"] = k in bounds
        curve.append(row)
    rounds = [{key: (v.tolist() if hasattr(v, "tolist") else v) for key, v in r.items()
               if key not in ("targets", "distance_m")} | {"targets": int(len(r["targets"]))}
              for r in ex.probe_rounds]
    return {"object": name, "label": label, "arm": arm, "probe": probe, "no_probes": no_probes, "noise_seed": noise_seed,
            "percent_error": round(res.error.percent, 3), "wraps": n, "explore_s": round(ex.wall_s, 1),
            "steps": int(ex.steps),
            "rounds": rounds, "curve": curve}


def table(path: Path) -> str:
    """The runs of the JSON-lines file ``path`` as a Markdown table (see the module's docstring)."""
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    width = max(sum(c["round_end"] for c in r["curve"]) for r in rows)
    head = ["object", "label", "sweeps"] + [f"round {i}" for i in range(1, width)] + ["excess / missing at the end"]
    out = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    for r in sorted(rows, key=lambda r: (r["object"], r["label"])):
        ends = [c for c in r["curve"] if c["round_end"]]
        cells = [f"{c['percent_error']:.2f} / {100 * c['coverage_3mm']:.0f} / {c['wraps']} / {c['wall_s']:.0f}"
                 for c in ends] + ["-"] * (width - len(ends))
        last = r["curve"][-1]
        split = f"{last['excess_percent']:.2f} / {last['missing_percent']:.2f}" if "excess_percent" in last else "-"
        out.append("| " + " | ".join([r["object"], r["label"], *cells, split]) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    from nonconvex_set import NONCONVEX_SET

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", nargs="+", default=["nonconvex"])
    ap.add_argument("--label", help="name of the setting measured (required unless --table)")
    ap.add_argument("--table", action="store_true", help="print --out's runs as a Markdown table and stop")
    ap.add_argument("--probe", action="append", default=[], metavar="KEY=VALUE",
                    help="a ProbeConfig field (repeatable), e.g. min_distance_m=0.02")
    ap.add_argument("--no-probes", action="store_true", help="the straight sweeps only")
    ap.add_argument("--every", type=int, default=24, help="score the estimate every this many wraps too")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--arm", default="default", help="built-in arm name or a URDF (explore3d arm writes one)")
    ap.add_argument("--out", type=Path, required=True, help="JSON-lines file (appended)")
    ap.add_argument("--noise-seed", type=int, default=None,
                    help="the sensor noise's seed (SensorConfig.seed; default: its default): one more sample")
    args = ap.parse_args(argv)
    if args.table:
        print(table(args.out))
        return 0
    if not args.label:
        ap.error("--label is required (the name of the setting measured)")
    groups = GROUPS | {"nonconvex": tuple(NONCONVEX_SET)}
    names = [n for o in args.objects for n in groups.get(o, (o,))]
    probe = {}
    for kv in args.probe:
        key, sep, val = kv.partition("=")
        if not sep:
            ap.error(f"--probe takes KEY=VALUE; got {kv!r}")
        probe[key] = _value(val)
    done = set()
    if args.out.exists():
        done = {(r["object"], r["label"]) for r in map(json.loads, args.out.read_text().splitlines()) if r}
    for name in names:
        if (name, args.label) in done:
            continue
        row = one(name, args.label, probe, args.no_probes, args.every, args.jobs, args.arm, args.noise_seed)
        with args.out.open("a") as f:
            f.write(json.dumps(row) + "\n")
        print(json.dumps({k: row[k] for k in ("object", "label", "percent_error", "wraps", "explore_s")}),
              [(c["wraps"], c["percent_error"], c["coverage_3mm"]) for c in row["curve"] if c["round_end"]],
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
