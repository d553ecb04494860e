"""Explore, reconstruct and score in one call: the library's main entry point.

``reconstruct_exploration`` uses only what the robot knows: the link surface points, the rough
centre it was told (as the inversion centre) and the rough bounding radius (points beyond it
cannot lie on the object and are dropped).  Scoring against the true shape happens afterwards.
The command line's ``explore3d run`` calls :func:`run`, so both give the same estimate for the
same configuration.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trimesh
from shapely.ops import unary_union

from explore3d.arm.urdf import load_arm
from explore3d.core.defaults import DEFAULT_A
from explore3d.core.validate import check_positive, check_vector
from explore3d.geometry.hull import check_method, check_a
from explore3d.geometry.metrics import check_volume, shape_error
from explore3d.reconstruction.carve import carve
from explore3d.reconstruction.hull_input import (
    OUTLIER_RATIO,
    hull_input_mask,
    reconstruct_points,
)
from explore3d.reconstruction.tabletop import cut_at_table, support_points
from explore3d.strategy.explore import Exploration, ExploreConfig, rough_bound, takes_phase
from explore3d.strategy.motion import carry_back, motion_trust
from explore3d.world.explore import explore
from explore3d.world.objects import cross_section
from explore3d.world.scene import settle_scene


@dataclass(frozen=True)
class Result:
    """An exploration, its reconstruction and its score.

    Attributes:
        exploration: what the arm gathered.
        hull: the :class:`~explore3d.geometry.hull.InverseHull` (2D planar, 3D otherwise), world frame.
        truth: the true shape (shapely Polygon planar, trimesh 3D), world frame.
        error: :class:`~explore3d.geometry.metrics.ShapeError` of ``hull`` against ``truth``.
        centre: (3,) the robot's rough centre, world frame, metres (the inversion centre; planar
            runs use its x-y components and cut the truth at its z).
        radius: the robot's rough bounding radius, metres: points farther than this from
            ``centre`` were dropped before the hull.
        n_points_used: how many of ``exploration.points`` the hull was built from (within ``radius``,
            not angular outliers: :func:`hull_input_mask`).
        carved: 3D runs with free space (``ExploreConfig.free_space``): the
            :class:`~explore3d.reconstruction.carve.CarveResult` of cutting the swept free space out of the hull,
            whose mesh is the estimate; else None (the estimate is the hull).
        cut: on a table, the estimate cut at the table's plane
            (:func:`explore3d.reconstruction.tabletop.cut_at_table`); else None.
        setup: the settled scene (:class:`explore3d.world.scene.SceneSetup`) of a scene other than the
            ideal one, else None; ``truth`` is then the object as it rested.
    """

    exploration: Exploration
    hull: object
    truth: object
    error: object
    centre: np.ndarray
    radius: float = math.nan
    n_points_used: int = -1
    carved: object | None = None
    cut: object | None = None
    setup: object | None = None

    @property
    def estimate(self):
        """The reconstructed shape: shapely Polygon (planar) or closed trimesh (3D: the hull, carved
        by the swept free space when there is some, cut at the table's plane on a table), world
        frame, metres."""
        if self.cut is not None:
            return self.cut
        return self.hull.shape() if self.carved is None else self.carved.mesh

    def summary(self) -> dict:
        """The figures of a run as a JSON-ready dict: :func:`exploration_summary`, ``n_points_used``,
        ``percent_error``, ``iou``, ``chamfer_m``, ``hausdorff_m``, ``true_size``, ``estimate_size``
        (m^2 planar, m^3 3D; ``size_unit``), ``centre_m`` and ``radius_m`` (the rough bound), and
        ``estimate_convex_hull``: the estimate's convex hull ``size`` (m^2 / m^3) and ``centre_m``
        (its centroid, world frame), what a grasp planner takes as the object's extent; carved runs
        add ``carved_m3``, ``hull_m3``, ``dropped_pieces_m3`` (the slivers the carving left
        beside the estimate's body, dropped: :func:`explore3d.geometry.bodies.one_body`) and
        ``trimmed_fins_m3`` (the thin fins it left on the body, trimmed:
        :func:`explore3d.reconstruction.carve.trim_fins`)."""
        e = self.error
        est = self.estimate
        if e.dim == 2:
            ch = est.convex_hull
            hull = {"size": float(ch.area), "centre_m": [float(ch.centroid.x), float(ch.centroid.y)]}
        else:
            ch = est.convex_hull
            hull = {"size": float(ch.volume), "centre_m": [float(x) for x in ch.center_mass]}
        carved = {} if self.carved is None else {"carved_m3": float(self.carved.carved_m3),
                                                 "hull_m3": float(self.hull.mesh.volume),
                                                 "dropped_pieces_m3": list(self.carved.dropped_m3),
                                                 "trimmed_fins_m3": float(self.carved.trimmed_m3)}
        return {**exploration_summary(self.exploration), "n_points_used": self.n_points_used,
                "estimate_convex_hull": hull, **carved,
                "percent_error": e.percent, "iou": e.iou, "chamfer_m": e.chamfer_m, "hausdorff_m": e.hausdorff_m,
                "true_size": e.true_size, "estimate_size": e.estimate_size,
                "size_unit": "m^2" if e.dim == 2 else "m^3",
                "centre_m": [float(x) for x in self.centre], "radius_m": float(self.radius)}


def exploration_summary(ex: Exploration) -> dict:
    """``n_wraps``, ``n_points``, ``n_contacts``, ``wall_s``, ``sim_s`` and ``steps`` of an exploration,
    and ``probe_rounds``: per round of probes its ``targets`` (how many), ``wraps`` added, the
    estimate's ``volume_m3`` and volume at stake ``stake_m3`` before it, their ratio
    ``stake_fraction`` and ``wall_s``; in a persistent world (a resting object the arm can move)
    also ``object_motion``: whether the robot's own readings say the object moved and how far the
    estimate's points agree (:func:`explore3d.strategy.motion.motion_trust`)."""
    rounds = [{"targets": int(len(r["targets"])), "wraps": int(r["wraps"]), "volume_m3": float(r["volume_m3"]),
               "stake_m3": float(r["stake_m3"]), "stake_fraction": float(r["stake_m3"] / r["volume_m3"]),
               "wall_s": float(r["wall_s"])} for r in ex.probe_rounds]
    return {"n_wraps": ex.n_wraps, "n_points": int(len(ex.points)), "n_contacts": ex.n_contacts,
            "wall_s": float(ex.wall_s), "sim_s": float(ex.sim_time_s), "steps": int(ex.steps),
            "probe_rounds": rounds,
            **({"object_motion": motion_trust(ex.moved, ex.point_wrap, ex.registrations)}
               if ex.config.scene.persistent and ex.moved is not None else {})}


def table_contacts(ex: Exploration) -> int:
    """How many of the exploration's localised contacts lay at the table (at most the scene's
    clearance above its known height) and were left out of the hull; 0 without a table."""
    if ex.table_z is None or ex.contacts is None or not len(ex.contacts):
        return 0
    return int(((ex.contacts.points[:, 2] <= ex.config.floor_z(ex.table_z)) & ~ex.contacts.self_contact).sum())


def sensed_z_band(ex: Exploration) -> tuple[float, float]:
    """The heights (z_lo, z_hi), world frame, metres, that a planar exploration's links swept: the
    arm planes' z (of the wrap base poses) +- half the link height.  All the robot sensed of the
    object's height; planar estimates are extruded over it, never over the true mesh's height."""
    z = np.array([float(np.asarray(p.T_world_base)[2, 3]) for p in ex.poses])
    h = 0.5 * float(ex.spec.link_height)
    return float(z.min()) - h, float(z.max()) + h


def extrusion_band(ex: Exploration, height: float | None = None) -> tuple[float, float]:
    """(z_lo, z_hi), world frame, metres, over which a planar estimate is extruded: the arm's
    :func:`sensed_z_band`, or ``height`` metres centred on it when given."""
    zlo, zhi = sensed_z_band(ex)
    if height is None:
        return zlo, zhi

    h = check_positive(height, "height (the extrusion height of a planar estimate, metres)")
    zc = 0.5 * (zlo + zhi)
    return zc - 0.5 * h, zc + 0.5 * h


def estimate_mesh(result: Result, height: float | None = None):
    """The estimate as a closed trimesh, world frame, metres.  3D: the inverse hull's mesh.
    Planar: the polygon extruded over :func:`extrusion_band` (the arm's sensed height band, or
    ``height`` metres centred on the arm's plane: the user's own knowledge of the object)."""
    est = result.estimate
    if result.exploration.config.mode != "planar":
        return est
    return extruded(est, result.exploration, height)


def extruded(polygon, ex: Exploration, height: float | None = None):
    """A planar exploration's estimate ``polygon`` (shapely, world x-y, m) as a closed trimesh
    extruded over :func:`extrusion_band` of ``ex`` (``height``: as there)."""
    zlo, zhi = extrusion_band(ex, height)
    m = trimesh.creation.extrude_polygon(polygon, zhi - zlo)
    m.apply_translation([0.0, 0.0, zlo])
    return m






class NoContactError(RuntimeError):
    """The exploration detected no contact at all.  ``exploration`` holds what was gathered
    (None if unknown), so callers can still report the wraps that were run."""

    def __init__(self, message: str, exploration: Exploration | None = None):
        super().__init__(message)
        self.exploration = exploration


class ReconstructionError(ValueError):
    """The points of an exploration did not give a hull (too few, degenerate, or not around the
    rough centre).  ``exploration`` holds what was gathered."""

    def __init__(self, message: str, exploration: Exploration | None = None):
        super().__init__(message)
        self.exploration = exploration












def reconstruct_exploration(ex: Exploration, centre, radius: float, a: float = DEFAULT_A, method: str = "exponential",
                            outlier_ratio: float | None = OUTLIER_RATIO):
    """Inverse hull of an exploration's points about the rough ``centre`` (3,), dropping points
    farther than ``radius`` metres from it and points far inside what other wraps saw in the same
    direction (:func:`reconstruct_points`).  Planar explorations use the x-y components.  On a
    table (``ex.table_z``) the lowest layer of points (within a link height) is also put on the
    table plane (:func:`explore3d.reconstruction.tabletop.support_points`)."""
    points, wrap = ex.points, ex.point_wrap
    if ex.table_z is not None and len(points):
        extra = support_points(points, ex.table_z, ex.spec.link_height)
        points = np.vstack([points, extra])
        wrap = np.r_[wrap, np.full(len(extra), -1)]
    return reconstruct_points(points, wrap, centre, radius, a=a, method=method, outlier_ratio=outlier_ratio)


def planar_truth(mesh, z: float):
    """The true 2D shape of the planar case: the mesh's cross-section at height ``z`` metres
    (x-y, world frame, metres).

    A mesh of several bodies (convex decompositions such as pybullet_data's ``*_vhacd.obj`` have
    touching or overlapping pieces, whose joint section trimesh gets wrong) is cut body by body:
    the union of the sections of positive-volume bodies minus those of inward-wound ones (cavities).
    """
    bodies = mesh.split(only_watertight=False) if mesh.body_count > 1 else [mesh]
    if len(bodies) == 1:
        return cross_section(mesh, z=z)
    solid, cavities = [], []
    for body in bodies:
        zlo, zhi = body.bounds[:, 2]
        if zlo < z < zhi:
            (solid if body.volume > 0 else cavities).append(cross_section(body, z=z))
    if not solid:
        return cross_section(mesh, z=z)  # raises: the plane misses the mesh
    region = unary_union(solid)
    return region.difference(unary_union(cavities)) if cavities else region


def rough_bound_or(mesh, centre=None, radius=None) -> tuple[np.ndarray, float]:
    """The robot's rough centre (3,) and radius (m): the given ones, checked, else
    :func:`~explore3d.strategy.explore.rough_bound` of the mesh's vertices."""
    c0, r0 = rough_bound(mesh.vertices)
    c = c0 if centre is None else check_vector(centre, "centre (the rough object centre x, y, z in metres)", 3)
    r = r0 if radius is None else check_positive(radius, "radius (the rough bounding radius in metres)")
    return c, r


#: The most triangles an object may have: PyBullet's createCollisionShape from arrays fails above
#: a vertex/index budget of its own (measured with pybullet 3.2.7: a 122,880-face mesh loads,
#: 184,320 faces fail with "createCollisionShape failed" after seconds of work).
MAX_OBJECT_FACES = 120_000


def check_run_inputs(mesh, spec, config, a, method, centre, radius) -> None:
    """Refuse, before any simulation, what :func:`run` cannot use: a ``mesh`` that is not a closed
    trimesh of finite coordinates or has more than :data:`MAX_OBJECT_FACES` faces, a ``config``
    that is not an :class:`ExploreConfig`, an ``a`` or ``method`` the inverse hull rejects, and an
    object that does not fit the arm ``spec``: a rough radius (``radius``, m, or the mesh's own:
    :func:`rough_bound_or`) beyond the arm's length (it cannot reach round it) or an object
    smaller than one link's width (nothing of its shape can be resolved).  ValueError (TypeError
    for wrong types) naming the fix."""

    if not isinstance(mesh, trimesh.Trimesh):
        raise TypeError(f"mesh must be a trimesh.Trimesh (e.g. explore3d.load_object('cube')); got {type(mesh).__name__}")
    if not isinstance(config, ExploreConfig):
        raise TypeError(f"config must be an explore3d.ExploreConfig (e.g. ExploreConfig(directions=4)); got "
                        f"{type(config).__name__}")
    bad = int((~np.isfinite(np.asarray(mesh.vertices, dtype=float))).any(axis=1).sum())
    if bad:
        raise ValueError(f"mesh has {bad} vertices with a non-finite (NaN or inf) coordinate; fix or remove them")
    if len(mesh.faces) > MAX_OBJECT_FACES:
        raise ValueError(f"mesh has {len(mesh.faces)} faces, more than the simulator takes ({MAX_OBJECT_FACES}); "
                         "simplify it (e.g. trimesh's simplify_quadric_decimation) first")
    check_volume(mesh, "mesh")
    check_a(a)
    check_method(method)
    _, radius = rough_bound_or(mesh, centre, radius)
    if radius > spec.reach:
        raise ValueError(f"the object's rough radius {radius:.3g} m exceeds the arm's length {spec.reach:.3g} m ({spec.name}: "
                         f"{spec.n_links} links of {spec.link_length:g} m): it cannot reach round it; use a smaller "
                         "object (load_object(size=), --size) or a longer arm (--arm)")
    across = float(np.max(mesh.extents))
    if across < spec.link_width:
        raise ValueError(f"the object is {across:.3g} m across, smaller than the arm's link width {spec.link_width:g} m: "
                         "the arm cannot resolve its shape; use a larger object (load_object(size=), --size) or a "
                         "finer arm (--arm)")


def estimate_exploration(ex: Exploration, centre, radius: float, a: float = DEFAULT_A, method: str = "exponential"):
    """What :func:`run` makes of an exploration, with no world: the wraps carried back onto the
    object when it moved (``config.scene.register_moved``), the inverse hull of the contacts
    about the rough ``centre`` (world frame, m) within ``radius`` (m), carved by the swept free
    space (3D), cut at the table the robot was told of.

    Returns ``(exploration, hull, carved, cut, estimate)``: the exploration (carried back), the
    :class:`~explore3d.geometry.hull.Hull`, the carving (None when not carved), the cut (None
    without a table) and the estimate (trimesh 3D, shapely Polygon planar).

    Raises:
        ReconstructionError: the contact points gave no hull."""
    config = ex.config
    if config.scene.register_moved:
        ex = carry_back(ex, centre, radius, a=a)
    try:
        hull = reconstruct_exploration(ex, centre, radius, a=a, method=method)
    except ValueError as exc:
        what = str(exc).split("; ")[0]  # inverse_hull's own fix hints are about its arguments, not the run
        n_used = int(hull_input_mask(ex.points, ex.point_wrap, centre, radius).sum())
        raise ReconstructionError(
            f"no shape from the {n_used} {'localised contacts' if config.points == 'contacts' else 'link points'} "
            f"within {radius:.3g} m of the rough centre ({what}); "
            "explore from more directions or with more attempts (ExploreConfig directions/attempts, --directions/"
            "--attempts) so the arm surrounds the object, or correct the rough centre/radius", exploration=ex,
        ) from None
    carved = None
    if config.mode == "3d" and config.free_space:
        carved = carve(hull.mesh, ex.swept)
    est = hull.shape() if carved is None else carved.mesh
    cut = None
    if ex.table_z is not None:
        cut = est = cut_at_table(est, ex.table_z)
    return ex, hull, carved, cut, est


def run(mesh, arm="default", config: ExploreConfig = ExploreConfig(), a: float = DEFAULT_A,
        method: str = "exponential", progress=None, *, centre=None, radius=None, seed: int = 0,
        setup=None, after_wrap=None) -> Result:
    """Explore ``mesh`` (closed trimesh, metres) with ``arm``, reconstruct, and score.

    Args:
        mesh: the object (given to the simulated world only).
        arm: built-in arm name, URDF path or :class:`~explore3d.arm.spec.ArmSpec`.
        config: how to explore.
        a: inverse-hull coarseness > 0; method: "exponential" or "spherical".
        progress: None, or ``progress(done, total)`` called after each wrap
            (:func:`~explore3d.strategy.explore.explore_robots`); one that takes a phase
            (``progress(done, total, phase)``) is also called with ``total`` None and the phase
            ``"reconstructing"`` and then ``"scoring"`` as those start.
        centre, radius: the rough location (3,), world frame, metres, and bounding radius (m) the
            robot is told (the user's rough bound of where the object is).  Default: the
            bounding-box centre of ``mesh`` and 1.05 times its largest vertex distance from it
            (:func:`~explore3d.strategy.explore.rough_bound`).
        seed: seed of the surface samples of the Chamfer/Hausdorff measures (3D).
        setup, after_wrap: the settled scene and the evaluation's per-wrap hook
            (:func:`~explore3d.world.explore.explore`); a scene other than the ideal one is settled here
            when ``setup`` is None, and the truth is the object as it rests.

    Raises:
        NoContactError: the arm touched nothing (the object is out of reach or too big).
        ReconstructionError: the contact points gave no hull (a ValueError).
    """

    spec = load_arm(arm)
    check_run_inputs(mesh, spec, config, a, method, centre, radius)
    if setup is None and not config.scene.ideal:
        setup = settle_scene(mesh, config.scene, spec, config.sim)
    truth = mesh if setup is None else setup.truth  # the object as it rests
    centre, radius = rough_bound_or(truth, centre, radius)
    ex = explore(mesh, arm, config, centre=centre, radius=radius, progress=progress, setup=setup,
                 after_wrap=after_wrap)
    if ex.n_contacts == 0:
        raise NoContactError(
            "the arm made no contact with the object: it is out of reach, too large for the arm, or the rough "
            "centre/radius is wrong; use a longer arm (arm=, --arm), a smaller object (load_object(size=), --size) "
            "or a correct rough bound (centre=/radius=, --centre/--radius)",
            exploration=ex,
        )
    phased = progress is not None and takes_phase(progress)
    if phased:
        progress(ex.n_wraps, None, "reconstructing")
    ex, hull, carved, cut, est = estimate_exploration(ex, centre, radius, a, method)
    truth = planar_truth(mesh, float(centre[2])) if config.mode == "planar" else truth
    if phased:
        progress(ex.n_wraps, None, "scoring")
    return Result(exploration=ex, hull=hull, truth=truth, error=shape_error(est, truth, seed=seed),
                  centre=centre, radius=radius, n_points_used=len(hull.points), carved=carved, cut=cut,
                  setup=setup)  # the hull's input


# --- a complete run: what `explore3d run` does -------------------------------------------------------












