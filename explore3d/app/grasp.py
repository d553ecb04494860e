"""Is an estimate good enough to grasp?  Grasps planned on a run's estimate, executed on the true
object, counted (``explore3d grasp RUN_DIR``).

For one run folder: ``n`` antipodal grasps (:func:`explore3d.grasp.antipodal.sample_grasps`) are
planned on each of four meshes, and each grasp is executed on the true object resting on a table
(:func:`explore3d.world.grasping.execute_grasps`):

- ``estimate``: the run's estimate (what the arm felt);
- ``truth``: the true mesh (the upper bound: what a perfect estimate would give);
- ``convex_hull``: the estimate's convex hull (what a planner given only the extent would do);
- ``early``: the inverse hull of the contacts of the first ``early_wraps`` wraps alone (points.ply's
  ``wrap`` < 8, about the run's rough centre, uncarved): what little exploring gives.

Planning is told the table's height (the truth's lowest point, where the execution puts the
table: a fact a robot is given), nothing else of the truth.  Success rates come with 95% Wilson
score intervals.  Frames: the run's world frame, metres.
"""
from __future__ import annotations

import io
import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from explore3d.app.export import read_points_ply
from explore3d.app.pictures import _plt
from explore3d.app.settings import RunError
from explore3d.core.io import atomic_write_bytes, atomic_write_text, json_text
from explore3d.core.settings import SceneConfig
from explore3d.core.validate import check_field
from explore3d.grasp.antipodal import GraspSet, SamplerConfig, sample_grasps
from explore3d.grasp.gripper import GripperSpec
from explore3d.reconstruction.hull_input import reconstruct_points
from explore3d.world.grasping import ExecutionConfig, Outcome, execute_grasps
from explore3d.world.objects import load_object
from explore3d.world.scene import settle_scene

#: The meshes grasps are planned on, in report order (module docstring).
SOURCES = ("estimate", "truth", "convex_hull", "early")

#: z of the two-sided 95% normal interval, for the Wilson score interval.
Z_95 = 1.959963984540054


@dataclass(frozen=True)
class GraspConfig:
    """How a run's estimate is tested by grasping (SI units).

    Attributes:
        n: grasps planned on each source.
        seed: seed of the planner (the same seed gives the same grasps and outcomes).
        early_wraps: the early estimate is built from the contacts of this many first wraps.
        gripper, sampler, execution: the gripper, the planner's candidates, the execution.
    """

    n: int = 20
    seed: int = 0
    early_wraps: int = 8
    gripper: GripperSpec = field(default_factory=GripperSpec)
    sampler: SamplerConfig = field(default_factory=SamplerConfig)
    execution: ExecutionConfig = field(default_factory=ExecutionConfig)

    def __post_init__(self):
        check_field(self, "n", lo=1, integer=True)
        check_field(self, "seed", lo=0, integer=True)
        check_field(self, "early_wraps", lo=1, integer=True)


def wilson_interval(k: int, n: int, z: float = Z_95) -> tuple[float, float]:
    """The Wilson score interval (lo, hi) of a success rate ``k`` / ``n`` (95% at the default
    ``z``); (0, 1) when ``n`` is 0."""
    if n <= 0:
        return 0.0, 1.0
    p = k / n
    d = 1.0 + z * z / n
    mid = (p + z * z / (2 * n)) / d
    half = z * math.sqrt(p * (1.0 - p) / n + z * z / (4 * n * n)) / d
    return max(0.0, mid - half), min(1.0, mid + half)


def _estimate_path(run_dir: Path, report: dict) -> Path:
    for name in report.get("files", []):
        if name.startswith("estimate.") and name.rsplit(".", 1)[-1] in ("obj", "stl", "ply", "off", "glb"):
            return run_dir / name
    raise RunError(f"{run_dir} has no estimate mesh in report.json's files; run 'explore3d run' into it again")


def run_truth(report: dict, mesh=None) -> tuple[trimesh.Trimesh, float]:
    """The true object of a run as it was explored (world frame; settled on its table in a
    table scene) and the table height its grasps are executed at (its lowest point), m.

    ``mesh``: the object as the run was given it (before settling); None: loaded again from
    report.json's object name, scale and size."""
    cfg = report["config"]
    if mesh is None:
        mesh = load_object(report["object"], scale=cfg.get("scale"), size=cfg.get("size"))
    scene = cfg["explore"].get("scene", {})
    if scene.get("table") and scene.get("resting"):
        setup = settle_scene(mesh, SceneConfig(**scene))
        return setup.truth, float(setup.table_z)
    return mesh, float(mesh.bounds[0, 2])


def early_estimate(run_dir: Path, report: dict, wraps: int) -> trimesh.Trimesh:
    """The inverse hull of the first ``wraps`` wraps' points of the run (points.ply), about the
    run's rough centre (module docstring).  ValueError when they give no hull."""
    points, props = read_points_ply(run_dir / "points.ply", with_properties=True)
    if "wrap" not in props:
        raise ValueError("points.ply has no wrap property")
    keep = props["wrap"] < wraps
    cfg = report["config"]
    hull = reconstruct_points(points[keep], props["wrap"][keep], cfg["centre_m"], cfg["radius_m"], a=report["a"],
                              method=report["method"])
    return hull.shape()


def plan_and_execute(truth, sources: dict, table_z: float, config: GraspConfig = GraspConfig(), progress=None) -> dict:
    """For each named mesh of ``sources`` (world frame), ``config.n`` grasps planned on it and
    executed on ``truth``: per source ``planned``, ``held``, ``rate`` (held over planned; None
    when none was planned), ``wilson_95`` (lo, hi), ``outcomes`` (each grasp's),
    ``push_median_m`` and ``push_max_m`` (how far closing moved the object,
    :attr:`~explore3d.world.grasping.GraspExecution.push_m`; None when none was planned), ``grasps``
    (:meth:`GraspSet.to_dicts`) and ``timings`` (wall-clock ``plan_s``, ``execute_s``).
    ``progress``: None, or ``progress(done, total, phase)`` as each source's planning and execution
    starts (grasps done of at most ``config.n`` per source)."""
    out = {}
    total, done = config.n * len(sources), 0
    for name, mesh in sources.items():
        if progress is not None:
            progress(done, total, f"planning on the {name.replace('_', ' ')}")
        t0 = time.perf_counter()
        grasps = sample_grasps(mesh, config.n, config.gripper, seed=config.seed, table_z=table_z,
                               config=config.sampler)
        t1 = time.perf_counter()
        if progress is not None:
            progress(done, total, f"executing the {name.replace('_', ' ')}'s grasps")
        runs = execute_grasps(truth, grasps, config.gripper, table_z, config.execution)
        t2 = time.perf_counter()
        held = sum(r.outcome is Outcome.HELD for r in runs)
        lo, hi = wilson_interval(held, len(runs))
        push = [r.push_m for r in runs]
        out[name] = {"planned": len(grasps), "held": int(held), "rate": held / len(runs) if runs else None,
                     "wilson_95": [lo, hi], "outcomes": [r.outcome.value for r in runs],
                     "push_median_m": float(np.median(push)) if push else None,
                     "push_max_m": float(np.max(push)) if push else None,
                     "timings": {"plan_s": t1 - t0, "execute_s": t2 - t1},
                     "grasps": [{**g, "outcome": r.outcome.value, "rise_m": r.rise_m, "push_m": r.push_m}
                                for g, r in zip(grasps.to_dicts(), runs)]}
        done += config.n
    return out


def grasp_run(run_dir, config: GraspConfig = GraspConfig(), pictures: bool = True, truth=None, progress=None) -> dict:
    """Plan and execute grasps for the run in ``run_dir`` (module docstring); adds a ``grasp``
    entry to its report.json (rates, intervals, the configuration) and its wall-clock times to
    the report's ``timings`` (``grasp_s``, and ``grasp`` per source: ``plan_s``, ``execute_s``),
    and writes ``grasps.json`` (every grasp with its pose and outcome) and, with ``pictures``,
    ``grasps.png``.  ``truth``: the object mesh the run was given (None: loaded again, see
    :func:`run_truth`).  ``progress``: as :func:`plan_and_execute`'s, and called with the phase
    ``"writing"`` as the files are written.  Returns the ``grasp`` entry."""
    run_dir = Path(run_dir)
    path = run_dir / "report.json"
    if not path.is_file():
        raise RunError(f"{path} not found: give a folder 'explore3d run' wrote")
    report = json.loads(path.read_text(encoding="utf-8"))
    if report.get("error"):
        raise RunError(f"the run in {run_dir} failed ({report['error']}): it has no estimate to grasp")
    if report.get("mode") != "3d":
        raise RunError(f"the run in {run_dir} is {report.get('mode')!r}: grasps need a 3D run's estimate")
    estimate = trimesh.load_mesh(_estimate_path(run_dir, report))
    truth, table_z = run_truth(report, truth)
    sources = {"estimate": estimate, "truth": truth, "convex_hull": estimate.convex_hull}
    skipped = {}
    try:
        sources["early"] = early_estimate(run_dir, report, config.early_wraps)
    except (ValueError, FileNotFoundError) as exc:
        skipped["early"] = str(exc).split("; ")[0]
    t0 = time.perf_counter()
    results = plan_and_execute(truth, sources, table_z, config, progress)
    if progress is not None:
        progress(config.n * len(sources), None, "writing")
    entry = {"config": asdict(config), "table_z_m": table_z, "skipped": skipped,
             **{name: {k: v for k, v in r.items() if k not in ("grasps", "timings")} for name, r in results.items()}}
    timings = report.setdefault("timings", {})
    timings["grasp"] = {name: r["timings"] for name, r in results.items()}
    e, t = results["estimate"], results["truth"]
    entry["estimate_over_truth"] = (e["rate"] / t["rate"]) if e["rate"] is not None and t["rate"] else None
    atomic_write_text(run_dir / "grasps.json", json_text({name: r["grasps"] for name, r in results.items()}))
    if pictures:
        atomic_write_bytes(run_dir / "grasps.png", grasp_picture(estimate, results["estimate"]["grasps"]))
    report["grasp"] = entry
    timings["grasp_s"] = time.perf_counter() - t0
    files = set(report.get("files", [])) | {"grasps.json"} | ({"grasps.png"} if pictures else set())
    report["files"] = sorted(files)
    atomic_write_text(path, json_text(report))
    return entry


def grasp_picture(mesh, grasps: list[dict]) -> bytes:
    """PNG bytes: ``mesh`` (grey) with each grasp as the segment between its contacts and a stub
    back along its approach, green where it held and red where it failed; three views."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # start-up: kept out of explore3d --help's

    plt = _plt()  # matplotlib on the Agg backend

    fig = plt.figure(figsize=(12, 4.4))
    V = np.asarray(mesh.vertices) * 1e3
    lo, hi = V.min(axis=0), V.max(axis=0)
    c, r = 0.5 * (lo + hi), 0.6 * float((hi - lo).max()) + 10.0
    for i, (elev, azim, title) in enumerate(((25, -60, "iso"), (90, -90, "top"), (0, -90, "front"))):
        ax = fig.add_subplot(1, 3, i + 1, projection="3d")
        ax.add_collection3d(Poly3DCollection(V[mesh.faces], facecolor=(0.6, 0.6, 0.65, 0.25),
                                             edgecolor=(0.4, 0.4, 0.45, 0.08), linewidths=0.2))
        for g in grasps:
            col = "tab:green" if g["outcome"] == Outcome.HELD.value else "tab:red"
            p = np.asarray(g["contacts_m"]) * 1e3
            T = np.asarray(g["pose"])
            ax.plot(p[:, 0], p[:, 1], p[:, 2], color=col, lw=1.6)
            back = T[:3, 3] * 1e3 - 30.0 * T[:3, 2]
            ax.plot([T[0, 3] * 1e3, back[0]], [T[1, 3] * 1e3, back[1]], [T[2, 3] * 1e3, back[2]], color=col,
                    lw=0.8, ls="--")
        ax.set_xlim(c[0] - r, c[0] + r)
        ax.set_ylim(c[1] - r, c[1] + r)
        ax.set_zlim(c[2] - r, c[2] + r)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=elev, azim=azim)
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_zlabel("z (mm)")
        ax.set_title(title)
    held = sum(g["outcome"] == Outcome.HELD.value for g in grasps)
    fig.suptitle(f"grasps planned on the estimate, executed on the truth: {held}/{len(grasps)} held "
                 "(green held, red failed; dashed: approach)")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()
