"""Run and report: :func:`run_and_report` explores, reconstructs and scores one object
(:func:`explore3d.app.pipeline.run`) and writes the run's folder (report.json, the estimate, its
URDF, points.ply, free space and pictures) all or nothing; what ``explore3d run`` and each sweep
run call.  :func:`write_result` writes a :class:`~explore3d.app.pipeline.Result`'s files.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path


from explore3d import __version__
from explore3d.app import pictures as pics
from explore3d.app.export import (
    DEFAULT_DENSITY_KG_M3,
    check_format,
    contact_properties,
    write_estimate_urdf,
    write_mesh,
    write_points_ply,
)
from explore3d.arm.urdf import load_arm
from explore3d.core.defaults import DEFAULT_A
from explore3d.core.interrupt import check_interrupt
from explore3d.core.io import StagedFolder, atomic_write_text, json_text
from explore3d.reconstruction.freespace import save_swept
from explore3d.strategy.explore import Exploration, ExploreConfig, takes_phase
from explore3d.world.calibration import calibrate_thickness
from explore3d.world.quality import contact_quality
from explore3d.world.scene import SceneWatch, settle_scene
from explore3d.app.pipeline import (NoContactError, ReconstructionError, Result, estimate_mesh,
    exploration_summary, extrusion_band, rough_bound_or, run, table_contacts)


def write_exploration_points(ex: Exploration, path):
    """Write ``ex.points`` as PLY with their wrap, attempt and link, and, when they are localised
    contacts, the :data:`~explore3d.app.export.CONTACT_PROPERTIES` of each (same order)."""
    extra = None
    if ex.config.points == "contacts" and ex.contacts is not None:
        extra = contact_properties(ex.contacts.select(ex.contacts.used))
    return write_points_ply(ex.points, path, ex.point_wrap, ex.point_attempt, ex.point_link, extra=extra)


def write_result(result: Result, mesh, out, fmt: str = "obj", pictures: bool = True, *,
                 density: float | None = None, height: float | None = None) -> list[str]:
    """Write a run's files into folder ``out`` (created) and return their names:

    * ``estimate.<fmt>`` (obj, stl, ply, off, glb): the estimate mesh (:func:`estimate_mesh`),
      world frame, metres; one closed, outward-wound volume that reloads as such with the
      loaders' default settings; planar runs: the polygon extruded over the arm's sensed height
      band (or ``height`` metres); ``estimate.urdf`` loading it in PyBullet with the mass and
      inertia of the estimate filled at ``density`` kg/m^3 (default
      :data:`~explore3d.app.export.DEFAULT_DENSITY_KG_M3`) (plus ``estimate.obj`` when ``fmt`` is not
      obj/stl);
    * ``estimate_polygon.json`` (planar): the polygon as a list of [x, y], metres, counter-clockwise;
    * ``points.ply``: the hull's input points with their wrap, attempt and link; localised
      contacts (the default) also with their normal, force, uncertainty, the face segment across
      the link's height and the interval along the link (:func:`write_exploration_points`);
    * ``free_space.npz`` (runs with free space): the space every attempt swept through
      (:func:`~explore3d.reconstruction.freespace.save_swept`), with which ``explore3d reconstruct
      --free-space`` carves the hull as the run did;
    * ``figure.png``/``views.png``, ``overview.png``, ``scene.png`` and ``signed_distance.png`` (the
      estimate coloured by its signed distance to the truth, mm:
      :func:`~explore3d.app.pictures.signed_distance_figure`) with ``pictures=True``.

    ``mesh`` is the explored object (closed trimesh, metres), used for the pictures only.  Files
    are written atomically.
    """

    fmt = check_format(fmt)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ex, estimate = result.exploration, result.estimate
    write_exploration_points(ex, out / "points.ply")
    names = ["points.ply"]
    if ex.swept:
        save_swept(ex.swept, out / "free_space.npz")
        names.append("free_space.npz")
    if ex.config.mode == "planar":
        ring = [[float(x), float(y)] for x, y in list(estimate.exterior.coords)[:-1]]
        atomic_write_text(out / "estimate_polygon.json", json.dumps(ring, indent=2) + "\n")
        names.append("estimate_polygon.json")
    est_mesh = estimate_mesh(result, height)
    mesh_name = f"estimate.{fmt}"
    write_mesh(est_mesh, out / mesh_name, fmt)
    write_estimate_urdf(mesh_name, out / "estimate.urdf", est_mesh,
                        density=DEFAULT_DENSITY_KG_M3 if density is None else density)
    names += [mesh_name, "estimate.urdf"] + ([] if fmt in ("obj", "stl") else ["estimate.obj"])  # PyBullet's copy
    if pictures:
        names += pics.run_pictures(out, ex, estimate, result.truth, mesh, result.error)
    return sorted(names)


@dataclass(frozen=True)
class OutputConfig:
    """What :func:`run_and_report` writes besides report.json.

    Attributes:
        fmt: estimate mesh format, one of :data:`~explore3d.app.export.MESH_FORMATS`.
        pictures: write the PNG pictures.
        quality: compute the contact-quality figures (:func:`~explore3d.world.quality.contact_quality`:
            evaluation only, against the true mesh, after the run).  Off by default: they need
            the recorded trajectories and cost more than the exploration (measured on 2 cores:
            cube 45 s exploring + 33 s quality; duck 34 s + 13 min).
        density: of the estimate body in estimate.urdf, kg/m^3.
        height: planar runs: extrude the estimate polygon over this many metres centred on the
            arm's plane; None: over the arm's sensed height band (:func:`sensed_z_band`).
    """

    fmt: str = "obj"
    pictures: bool = True
    quality: bool = False
    density: float = DEFAULT_DENSITY_KG_M3
    height: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "fmt", check_format(self.fmt))
        for name in ("pictures", "quality"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be True or False; got {getattr(self, name)!r}")
        d = self.density
        if isinstance(d, bool) or not isinstance(d, (int, float)) or not (math.isfinite(d) and d > 0):
            raise ValueError(f"density must be a positive number of kg/m^3; got {d!r}")
        h = self.height
        if h is not None and (isinstance(h, bool) or not isinstance(h, (int, float)) or not (math.isfinite(h) and h > 0)):
            raise ValueError(f"height must be None or a positive number of metres; got {h!r}")


#: Every file name :func:`run_and_report` can write into its folder (report.json and what
#: :func:`write_result` writes, any format): a run replaces or removes all of them, so a folder
#: never mixes two runs.
RUN_FILES = frozenset({"report.json", "points.ply", "free_space.npz", "estimate_polygon.json", "estimate.urdf",
                       "figure.png", "views.png", "overview.png", "scene.png", "signed_distance.png",
                       *(f"estimate.{f}" for f in ("obj", "stl", "ply", "off", "glb"))})


#: Test hook (seconds): :func:`run_and_report` sleeps this long after writing the estimate files
#: into its staging folder and before report.json and the switch, so tests can interrupt or kill a
#: run while it writes.  Unset or empty: no pause.
WRITE_PAUSE_ENV = "EXPLORE3D_TEST_WRITE_PAUSE_S"


def _test_write_pause() -> None:
    v = os.environ.get(WRITE_PAUSE_ENV)
    if v:
        time.sleep(float(v))


def package_versions() -> dict:
    """Versions of explore3d and its main dependencies (for report.json)."""
    out = {"explore3d": __version__}
    for name in ("numpy", "scipy", "trimesh", "pybullet", "shapely"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def run_and_report(mesh, arm="default", config: ExploreConfig = ExploreConfig(), out=None, *,
                   output: OutputConfig = OutputConfig(), a: float = DEFAULT_A, method: str = "exponential",
                   seed: int = 0, centre=None, radius=None, calibrate: bool = False, progress=None,
                   object_name: str = "object", source: dict | None = None) -> tuple[Result, dict]:
    """Explore, reconstruct and score ``mesh`` like :func:`run`, then write report.json and the
    files of :func:`write_result` into folder ``out``: what ``explore3d run`` does.

    Args:
        mesh, arm, config, a, method, seed, centre, radius, progress: as for :func:`run`.
        out: output folder (created).
        output: what to write (:class:`OutputConfig`).
        calibrate: first calibrate the contact thickness on the known 60 mm ball
            (:func:`~explore3d.world.calibration.calibrate_thickness`, never ``mesh``) and explore with it
            (link points only: ``config.points == "links"``; ValueError otherwise).
        object_name: how the report names the object; source: more facts about how ``mesh`` was
            made (e.g. ``{"scale": ..., "size": ...}``), copied into ``report["config"]``.

    Returns:
        the :class:`Result` and the report (the dict written to ``out/report.json``).  Its
        ``timings`` (seconds): ``calibration_s``, ``band_s`` (the contact band: measured the first
        time for a setting, else read from the cache), ``explore_s`` (the wraps), ``run_s``
        (exploration, reconstruction and scoring), ``quality_s`` (only with ``output.quality``),
        ``write_s`` (files and pictures), ``total_s``.

    Raises:
        NoContactError, ReconstructionError: as :func:`run`, after writing report.json (with an
            ``error`` entry) and points.ply (if any points) into ``out``.

    All or nothing: every file is written into a hidden staging folder in ``out``
    (:class:`~explore3d.core.io.StagedFolder`) and the folder is switched to the new set at the end, so
    ``out`` never mixes two runs among :data:`RUN_FILES`:

    * a completed run leaves exactly its files (an earlier run's files it does not write, e.g. the
      pictures after ``pictures=False`` or another mesh format, are removed);
    * a failed run (NoContactError, ReconstructionError) leaves its report.json (with ``error``)
      and points.ply (if any points), and none of an earlier run's estimate files;
    * an interrupted run (KeyboardInterrupt), any other exception or a kill before the switch
      leaves ``out`` as it was (the earlier set, or no run files); the switch itself runs with
      SIGINT/SIGTERM deferred, and a SIGKILL inside it is finished by the next run into ``out``.
      Whenever ``out/report.json`` exists, the run files beside it are that run's complete set;
    * the next run into ``out`` removes the staging folders and ``.*.part*`` temporaries of killed
      runs (their pid no longer alive): :func:`explore3d.core.io.stale_leftovers`.

    Test hook: the environment variable :data:`WRITE_PAUSE_ENV` pauses the writing.
    """


    if out is None:
        raise ValueError("run_and_report needs an output folder: pass out=")
    if not isinstance(output, OutputConfig):
        raise ValueError(f"output must be an OutputConfig; got {type(output).__name__}")
    t_start = time.perf_counter()
    timings = {}
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    spec = load_arm(arm)
    bound_given = centre is not None or radius is not None
    setup = watch = None
    if not config.scene.ideal:  # the evaluation's setup: the object settled on its table

        t0 = time.perf_counter()
        setup = settle_scene(mesh, config.scene, spec, config.sim)
        timings["settle_s"] = time.perf_counter() - t0
        watch = SceneWatch(setup)
    centre, radius = rough_bound_or(mesh if setup is None else setup.truth, centre, radius)
    report = {
        "object": object_name, "mode": config.mode, "arm": arm if isinstance(arm, str) else spec.name,
        "a": a, "method": method,
        "config": {"explore": config.to_dict(), "arm": spec.to_dict(), "a": a, "method": method, "seed": seed,
                   "centre_m": [float(x) for x in centre], "radius_m": float(radius),
                   "rough_bound": "given" if bound_given else "rough_bound(mesh)",
                   "format": output.fmt, "pictures": output.pictures, "quality": output.quality,
                   "density_kg_m3": float(output.density), "height_m": output.height, **(source or {})},
        "versions": package_versions(),
        "timings": timings,
    }
    if calibrate and config.points != "links":
        raise ValueError("calibrate corrects the thickness of the paper's link points; the localised contacts "
                         "(the default) lie on the links' surfaces already: explore with points='links' "
                         "(--points links) to calibrate, or drop calibrate (--calibrate)")
    if calibrate:
        t0 = time.perf_counter()
        cal = calibrate_thickness(spec, config)
        timings["calibration_s"] = time.perf_counter() - t0
        config = dataclasses.replace(config, face_offset=cal.face_offset_m)
        report["calibration"] = cal.to_dict()
        report["config"]["explore"] = config.to_dict()
    if output.quality:  # the quality figures read the recorded trajectories
        config = dataclasses.replace(config, record=True)
        report["config"]["explore"] = config.to_dict()
    with StagedFolder(out, RUN_FILES, last="report.json") as staged:  # discarded unless committed
        return _run_into(staged, report, timings, t_start, mesh, spec, config, output, a, method, seed,
                         centre, radius, progress, setup, watch)


def _run_into(staged, report, timings, t_start, mesh, spec, config, output, a, method, seed, centre, radius,
              progress, setup, watch):
    """The rest of :func:`run_and_report`: run, write into ``staged.path``, then switch ``out``."""
    stage = staged.path

    def finish():
        timings["total_s"] = time.perf_counter() - t_start
        atomic_write_text(stage / "report.json", json_text(report))
        check_interrupt()  # an interrupt swallowed somewhere: do not switch the folder
        staged.commit()

    t0 = time.perf_counter()
    try:
        res = run(mesh, spec, config, a=a, method=method, progress=progress, centre=centre, radius=radius,
                  seed=seed, setup=setup, after_wrap=None if watch is None else watch.after_wrap)
    except (NoContactError, ReconstructionError) as exc:
        ex = exc.exploration
        timings["run_s"] = time.perf_counter() - t0
        if ex is not None:
            timings["explore_s"] = float(ex.wall_s)
            report.update(exploration_summary(ex))
            if len(ex.points):
                write_exploration_points(ex, stage / "points.ply")
        report["error"] = str(exc)
        finish()
        raise
    timings["run_s"] = time.perf_counter() - t0
    timings["explore_s"] = float(res.exploration.wall_s)
    timings["band_s"] = float(res.exploration.band_s)
    summary = res.summary()
    for k in ("centre_m", "radius_m"):  # already in config
        summary.pop(k)
    report.update(summary)
    report["errors"] = res.error.to_dict()
    if setup is not None:  # evaluation: the settled scene, the object's true drift, false detections
        report["scene"] = {**setup.to_dict(), **watch.summary(res.exploration),
                           "table_contacts_dropped": int(table_contacts(res.exploration))}
    report["contact_band"] = res.exploration.band.to_dict()  # per joint, rad, and how it was measured
    if config.mode == "planar":
        report["section_z_m"] = float(res.centre[2])  # the arm's plane passes through the rough centre
        report["estimate_z_band_m"] = list(extrusion_band(res.exploration, output.height))
    if output.quality:
        t0 = time.perf_counter()
        report["contact_quality"] = contact_quality(res.exploration, mesh if res.setup is None else res.truth).to_dict()  # evaluation only
        timings["quality_s"] = time.perf_counter() - t0
    check_interrupt()
    if progress is not None and takes_phase(progress):
        progress(res.exploration.n_wraps, None, "writing")
    t0 = time.perf_counter()
    files = write_result(res, mesh if res.setup is None else res.truth, stage, output.fmt, pictures=output.pictures, density=output.density,
                         height=output.height)
    timings["write_s"] = time.perf_counter() - t0
    _test_write_pause()
    report["files"] = sorted(files + ["report.json"])
    finish()
    return res, report
