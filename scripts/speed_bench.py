"""Exploration wall time, physics steps, wraps and volume error of default 3D runs, one process per
run, several code trees interleaved (A, B, A, B, ...) so that they share the machine's load:

    python scripts/speed_bench.py --trees /work/wt-a819 /work/wt-speed --objects cube sphere --repeats 2
    python scripts/speed_bench.py --one cube           # one run in this process's explore3d: a JSON line

Each run is ``explore3d.run(load_object(NAME), "default", ExploreConfig(jobs=1, **CONFIG))`` (one process:
the work is in the timed process) after the band is cached.  Prints one JSON line per run and a
summary (medians; ratios against the first tree; time per wrap).
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time


def one(name: str, seed: int, config: dict) -> dict:
    import dataclasses

    import explore3d
    from explore3d import ExploreConfig, load_object, run

    fields = {f.name for f in dataclasses.fields(ExploreConfig)}  # older trees lack newer keys (probes)
    cfg = ExploreConfig(jobs=1, **{k: v for k, v in config.items() if k in fields})
    t, c = time.perf_counter(), time.process_time()
    res = run(load_object(name), "default", cfg, seed=seed)
    cpu = time.process_time() - c  # this process's CPU time (jobs=1: all the work): robust to other jobs
    ex = res.exploration
    return {"object": name, "file": explore3d.__file__, "wall_s": round(ex.wall_s, 3),
            "run_s": round(time.perf_counter() - t, 3), "cpu_s": round(cpu, 3), "steps": int(ex.steps), "n_wraps": int(ex.n_wraps),
            "s_per_wrap": round(ex.wall_s / ex.n_wraps, 4), "steps_per_wrap": round(ex.steps / ex.n_wraps, 1),
            "us_per_step": round(1e6 * ex.wall_s / max(ex.steps, 1), 1),
            "percent_error": round(float(res.error.percent), 4), "n_points": int(len(ex.points))}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--one", help="run one object in this process and print a JSON line")
    ap.add_argument("--trees", nargs="+", help="code trees (PYTHONPATH) to compare, the first is the reference")
    ap.add_argument("--objects", nargs="+", default=["cube"])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", help="append the JSON lines to this file")
    ap.add_argument("--config", default="{}", help='ExploreConfig keywords as JSON, e.g. \'{"directions": 12, "probes": null}\' '
                    "(keys a tree does not know are left out)")
    a = ap.parse_args(argv)
    if a.one:
        print(json.dumps(one(a.one, a.seed, json.loads(a.config))), flush=True)
        return
    rows = []
    for rep in range(a.repeats):
        for obj in a.objects:
            order = a.trees if rep % 2 == 0 else a.trees[::-1]  # alternate who goes first
            for tree in order:
                env = dict(os.environ, PYTHONPATH=tree)
                out = subprocess.run([sys.executable, os.path.abspath(__file__), "--one", obj, "--seed", str(a.seed),
                                      "--config", a.config],
                                     env=env, capture_output=True, text=True, cwd=tree)
                line = [l for l in out.stdout.splitlines() if l.startswith("{")]
                if out.returncode or not line:
                    print(f"FAILED {tree} {obj}: {out.stderr[-2000:]}", file=sys.stderr)
                    continue
                r = dict(json.loads(line[-1]), tree=tree, rep=rep, load1=os.getloadavg()[0])
                rows.append(r)
                print(json.dumps(r), flush=True)
                if a.out:
                    with open(a.out, "a") as fh:
                        fh.write(json.dumps(r) + "\n")
    print("summary (medians):")
    for obj in a.objects:
        ref = None
        for tree in a.trees:
            rs = [r for r in rows if r["object"] == obj and r["tree"] == tree]
            if not rs:
                continue
            keys = ["wall_s", "s_per_wrap", "steps", "n_wraps", "us_per_step", "percent_error"]
            keys += ["cpu_s"] if all("cpu_s" in r for r in rs) else []
            med = {k: statistics.median(r[k] for r in rs) for k in keys}
            ref = ref or med
            print(json.dumps({"object": obj, "tree": tree, "n": len(rs), **{k: round(v, 4) for k, v in med.items()},
                              "time_ratio_vs_first": round(med["wall_s"] / ref["wall_s"], 3),
                              "per_wrap_ratio_vs_first": round(med["s_per_wrap"] / ref["s_per_wrap"], 3)}))


if __name__ == "__main__":
    main()
