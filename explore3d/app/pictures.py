"""Pictures of an exploration (matplotlib, Agg backend: no display needed; PNG files, atomic).

* :func:`planar_figure`: the paper's figure style: the arm (joint positions) and link surface
  points of each attempt coloured by wrap, the generated polygon over the true one, a legend and
  the percent error in the title.
* :func:`views_figure`: estimate (blue) over truth (grey, translucent) from several view
  directions with matplotlib's ``plot_trisurf``.
* :func:`scene_image`: PyBullet's TinyRenderer (DIRECT client, no GUI) of the truth mesh and the
  arm at one attempt's final joint angles.
* :func:`overview_figure`: one page with views and the numbers.
* :func:`signed_distance_figure`: the estimate coloured by its signed distance to the truth, mm
  (:func:`signed_distance_mm`; positive outside the truth: where the estimate is too big), a
  diverging colormap centred on 0 with a colorbar.

All coordinates are metres in the world frame (= the object's own frame).
"""
from __future__ import annotations

import logging
import tempfile
from pathlib import Path

import numpy as np
import shapely
import trimesh
from scipy.spatial.transform import Rotation

from explore3d.arm.kinematics import link_transforms
from explore3d.arm.urdf import arm_urdf
from explore3d.core.io import atomic_path
from explore3d.core.quiet import quiet_c_output
from explore3d.geometry.metrics import boundary_samples
from explore3d.geometry.sdf import SignedDistance


def _plt():
    import matplotlib  # start-up: matplotlib kept out of explore3d --help's; the Agg backend first

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt  # start-up: as above

    return plt


def _save(fig, path) -> Path:
    plt = _plt()
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def _rings(geom):
    """Exterior rings ((k, 2) arrays) of a shapely Polygon or MultiPolygon."""
    polys = getattr(geom, "geoms", [geom])
    return [np.asarray(p.exterior.coords) for p in polys]


def arm_polylines(exploration):
    """Per wrap, per attempt: (n_links + 1, 2) joint and tip positions in the world x-y plane, metres."""
    out = []
    spec = exploration.spec
    for wrap in exploration.attempts:
        rows = []
        for att in wrap:
            T = link_transforms(spec, att.q, att.T_world_base)  # (n, 4, 4) T_world_link
            tip = T[-1] @ np.array([spec.link_length, 0.0, 0.0, 1.0])
            rows.append(np.vstack([T[:, :2, 3], tip[:2]]))
        out.append(rows)
    return out


def _err_title(err) -> str:
    return "" if err is None else f" - error {err.percent:.2f} %, IoU {err.iou:.3f}"


def planar_figure(exploration, estimate_polygon, truth_polygon, path, err=None, title: str = "") -> Path:
    """Paper-style planar figure (PNG) at ``path``; returns it.

    Args:
        exploration: an :class:`explore3d.strategy.explore.Exploration` in planar mode (points (m, 2)).
        estimate_polygon, truth_polygon: shapely polygons, world x-y, metres.
        err: optional :class:`explore3d.geometry.metrics.ShapeError` for the title.
    """
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 6))
    cmap = plt.get_cmap("tab10")
    P = np.asarray(exploration.points)[:, :2]
    lines = arm_polylines(exploration)
    for w, rows in enumerate(lines):
        c = cmap(w % 10)
        for k, xy in enumerate(rows):
            ax.plot(xy[:, 0], xy[:, 1], "-o", color=c, ms=2.5, lw=1.0, alpha=0.45 + 0.55 * (k + 1) / len(rows),
                    label=f"wrap {w + 1}: arm" if k == 0 else None)
        sel = exploration.point_wrap == w
        ax.plot(P[sel, 0], P[sel, 1], ".", color=c, ms=3, label=f"wrap {w + 1}: link points")
    for i, ring in enumerate(_rings(truth_polygon)):
        ax.fill(ring[:, 0], ring[:, 1], color="0.6", alpha=0.35, label="true shape" if i == 0 else None)
    for i, ring in enumerate(_rings(estimate_polygon)):
        ax.plot(ring[:, 0], ring[:, 1], "-", color="crimson", lw=2, label="generated shape" if i == 0 else None)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    ax.set_title((title or "planar exploration") + _err_title(err))
    return _save(fig, path)


#: (elevation, azimuth) in degrees of the views of :func:`views_figure`.
VIEWS = ((25.0, -60.0), (90.0, -90.0), (0.0, -90.0), (0.0, 0.0))
VIEW_NAMES = ("iso", "top", "front", "side")

#: At most this many link points are drawn in a 3D view (readability and file size).
MAX_DRAWN_POINTS = 3000


def _draw_mesh_views(fig, axes_slots, estimate_mesh, truth_mesh, points=None):
    lo = np.minimum(estimate_mesh.bounds[0], truth_mesh.bounds[0])
    hi = np.maximum(estimate_mesh.bounds[1], truth_mesh.bounds[1])
    c, r = (lo + hi) / 2.0, float((hi - lo).max()) / 2.0
    P = None
    if points is not None and len(points):
        P = np.asarray(points, dtype=float)
        P = P[np.all(np.abs(P - c) <= r, axis=1)]  # 3D axes do not clip: drop points outside the view
        if len(P) > MAX_DRAWN_POINTS:  # fixed subsample: the same picture for the same run
            P = P[np.random.default_rng(0).choice(len(P), MAX_DRAWN_POINTS, replace=False)]
    for slot, (elev, azim), name in zip(axes_slots, VIEWS, VIEW_NAMES):
        ax = fig.add_subplot(*slot, projection="3d")
        v, f = truth_mesh.vertices, truth_mesh.faces
        ax.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=f, color="0.6", alpha=0.25, linewidth=0)
        v, f = estimate_mesh.vertices, estimate_mesh.faces
        ax.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=f, color="tab:blue", alpha=0.6,
                        edgecolor="navy", linewidth=0.2)
        if P is not None and len(P):
            ax.scatter(P[:, 0], P[:, 1], P[:, 2], s=1, color="crimson", alpha=0.4)
        ax.set_xlim(c[0] - r, c[0] + r)
        ax.set_ylim(c[1] - r, c[1] + r)
        ax.set_zlim(c[2] - r, c[2] + r)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=elev, azim=azim)
        ax.set_title(name, fontsize=9)
        ax.tick_params(labelsize=6)


def views_figure(estimate_mesh, truth_mesh, path, points=None, err=None, title: str = "") -> Path:
    """Estimate (blue) vs truth (grey) meshes (trimesh, metres) from :data:`VIEWS`; PNG at ``path``.
    ``points``: optional (m, 3) link points drawn in red."""
    plt = _plt()
    fig = plt.figure(figsize=(10, 10))
    _draw_mesh_views(fig, [(2, 2, i + 1) for i in range(4)], estimate_mesh, truth_mesh, points)
    fig.suptitle((title or "estimate (blue) vs truth (grey)") + _err_title(err))
    return _save(fig, path)


def scene_image(truth_mesh, spec, attempt, width: int = 480, height: int = 360) -> np.ndarray:
    """(height, width, 3) uint8 RGB image from PyBullet's TinyRenderer (DIRECT client) of the truth
    mesh (metres, world frame) and the arm ``spec`` at ``attempt.q`` (rad) on ``attempt.T_world_base``."""
    with quiet_c_output():  # PyBullet's banners: import, connect, the renderer
        return _scene_image(truth_mesh, spec, attempt, width, height)


def _scene_image(truth_mesh, spec, attempt, width: int, height: int) -> np.ndarray:
    import pybullet as p  # start-up: kept out of explore3d --help's

    cid = p.connect(p.DIRECT)
    try:
        v = np.asarray(truth_mesh.vertices, dtype=float)
        idx = np.asarray(truth_mesh.faces, dtype=np.int32).reshape(-1)
        vis = p.createVisualShape(p.GEOM_MESH, vertices=v.tolist(), indices=idx.tolist(),
                                  rgbaColor=[0.7, 0.7, 0.7, 1.0], physicsClientId=cid)
        p.createMultiBody(baseMass=0.0, baseVisualShapeIndex=vis, physicsClientId=cid)
        with tempfile.TemporaryDirectory() as d:
            urdf = Path(d) / "arm.urdf"
            urdf.write_text(arm_urdf(spec))
            arm = p.loadURDF(str(urdf), useFixedBase=True, physicsClientId=cid)
        T = np.asarray(attempt.T_world_base, dtype=float)
        quat_xyzw = Rotation.from_matrix(T[:3, :3]).as_quat()  # PyBullet order (x, y, z, w)
        p.resetBasePositionAndOrientation(arm, T[:3, 3].tolist(), quat_xyzw.tolist(), physicsClientId=cid)
        revolute = [j for j in range(p.getNumJoints(arm, physicsClientId=cid))
                    if p.getJointInfo(arm, j, physicsClientId=cid)[2] == p.JOINT_REVOLUTE]
        for j, qj in zip(revolute, np.asarray(attempt.q, dtype=float)):
            p.resetJointState(arm, j, float(qj), physicsClientId=cid)
        lo, hi = truth_mesh.bounds
        target = ((lo + hi) / 2.0).tolist()
        dist = 2.0 * float(np.linalg.norm(hi - lo)) + 0.05
        view = p.computeViewMatrixFromYawPitchRoll(target, dist, 30.0, -35.0, 0.0, 2, physicsClientId=cid)
        proj = p.computeProjectionMatrixFOV(40.0, width / height, 0.01, 10.0, physicsClientId=cid)
        img = p.getCameraImage(width, height, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=cid)
    finally:
        p.disconnect(cid)
    rgba = np.reshape(np.asarray(img[2], dtype=np.uint8), (height, width, 4))
    return rgba[:, :, :3].copy()


def overview_figure(path, numbers: dict, estimate_mesh=None, truth_mesh=None, points=None, scene=None,
                    estimate_polygon=None, truth_polygon=None, title: str = "") -> Path:
    """One-page overview PNG: views (3D meshes, or the 2D polygons), an optional rendered scene
    ((h, w, 3) uint8) and a text panel of ``numbers`` (name -> value)."""
    plt = _plt()
    fig = plt.figure(figsize=(12, 8))
    if estimate_mesh is not None:
        _draw_mesh_views(fig, [(2, 3, 1), (2, 3, 2), (2, 3, 4), (2, 3, 5)], estimate_mesh, truth_mesh, points)
    elif estimate_polygon is not None:
        ax = fig.add_subplot(1, 3, (1, 2))
        for ring in _rings(truth_polygon):
            ax.fill(ring[:, 0], ring[:, 1], color="0.6", alpha=0.4, label="true shape")
        for ring in _rings(estimate_polygon):
            ax.plot(ring[:, 0], ring[:, 1], "-", color="crimson", lw=2, label="generated shape")
        if points is not None:
            P = np.asarray(points)
            ax.plot(P[:, 0], P[:, 1], ".", ms=2, color="tab:blue", label="link points")
        ax.set_aspect("equal")
        ax.legend(fontsize=8)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    if scene is not None:
        ax = fig.add_subplot(2, 3, 3)
        ax.imshow(scene)
        ax.set_axis_off()
        ax.set_title("scene (TinyRenderer)", fontsize=9)
    ax = fig.add_subplot(2, 3, 6)
    ax.set_axis_off()
    lines = []
    for k, v in numbers.items():
        if isinstance(v, float):
            v = f"{v:.4g}"
        lines.append(f"{k}: {v}")
    ax.text(0.0, 1.0, "\n".join(lines), va="top", family="monospace", fontsize=9, transform=ax.transAxes)
    fig.suptitle(title or "explore3d overview")
    return _save(fig, path)


#: Diverging colormap of :func:`signed_distance_figure` (red: estimate outside the truth, blue: inside).
SD_CMAP = "RdBu_r"

#: The colour scale of :func:`signed_distance_figure` spans +- this percentile of |distance| (a few
#: stray vertices do not wash out the rest; the colorbar's arrows mark values beyond it) ...
SD_PERCENTILE = 98.0
#: ... and at least this many mm (a near-perfect estimate is not coloured by its float noise).
SD_MIN_SCALE_MM = 0.1


def signed_distance_mm(estimate, truth) -> np.ndarray:
    """Signed distance of the estimate to the true surface, mm, positive outside the truth.

    Args:
        estimate, truth: closed trimesh meshes (metres, world frame), or shapely polygons (planar).

    Returns:
        (v,) at the estimate mesh's vertices, or (m,) at
        :func:`~explore3d.geometry.metrics.boundary_samples` of the estimate polygon (400 samples plus its
        vertices; evaluation only: it reads the truth).
    """
    if hasattr(estimate, "exterior") or hasattr(estimate, "geoms"):
        P = boundary_samples(estimate, 400)
        pts = shapely.points(P)
        d = shapely.distance(truth.boundary, pts)
        inside = shapely.contains(truth, pts)
        return 1e3 * np.where(inside, -d, d)

    return 1e3 * SignedDistance(truth)(np.asarray(estimate.vertices, dtype=float))


def _sd_scale(sd_mm: np.ndarray) -> float:
    a = np.abs(sd_mm[np.isfinite(sd_mm)])
    return max(float(np.percentile(a, SD_PERCENTILE)) if a.size else 0.0, SD_MIN_SCALE_MM)


#: The truth's edges between faces meeting at more than this angle are drawn (its outline) in
#: :func:`signed_distance_figure`; a smooth surface's tessellation stays undrawn.
TRUTH_EDGE_ANGLE_DEG = 30.0

#: :func:`subdivided` splits edges longer than the estimate's largest extent over this.
SD_EDGE_DIVISOR = 30.0


def subdivided(mesh, divisor: float = SD_EDGE_DIVISOR):
    """A copy of ``mesh`` (trimesh, metres) with no edge longer than its largest extent / ``divisor``
    (:func:`trimesh.remesh.subdivide_to_size`, at most 8 rounds): the same surface, with vertices
    inside its faces where a picture colours per vertex."""
    V, F = trimesh.remesh.subdivide_to_size(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces),
                                            max_edge=float(np.max(mesh.extents)) / divisor, max_iter=8)
    return trimesh.Trimesh(V, F, process=False)


def signed_distance_figure(estimate, truth, path, title: str = "", views=VIEWS[:2], thumbnail: bool = False) -> Path:
    """PNG at ``path``: the estimate coloured by :func:`signed_distance_mm` against the truth.

    3D (trimesh meshes, metres): the estimate is first :func:`subdivided` (a hull's large faces
    bridging a concavity have their vertices on the surface: only their interior is wrong), then
    each face takes the mean of its vertices' distances, drawn from ``views`` ((elevation, azimuth)
    degrees) with the truth's outline (edges sharper than :data:`TRUTH_EDGE_ANGLE_DEG`) in grey.
    Planar (shapely polygons): the estimate's boundary samples coloured, the truth's outline in
    grey.  ``thumbnail``: one small view (the sweep report's table).  A symmetric diverging scale
    (:data:`SD_CMAP`, +- :data:`SD_PERCENTILE` of |distance|) with a colorbar in mm."""
    from matplotlib.colors import Normalize  # start-up: matplotlib kept out of explore3d --help's

    plt = _plt()
    planar = hasattr(estimate, "exterior") or hasattr(estimate, "geoms")
    if not planar:
        estimate = subdivided(estimate)
    sd = signed_distance_mm(estimate, truth)
    m = _sd_scale(sd)
    norm, cmap = Normalize(-m, m), plt.get_cmap(SD_CMAP)
    views = views[:1] if thumbnail else views
    n = 1 if planar else len(views)
    fig = plt.figure(figsize=(3.4, 2.8) if thumbnail else (5.0 * n + 1.0, 5.0))
    axes = []
    if planar:
        ax = fig.add_subplot(1, 1, 1)
        for ring in _rings(truth):
            ax.plot(ring[:, 0], ring[:, 1], "-", color="0.5", lw=1.0)
        P = boundary_samples(estimate, 400)
        ax.scatter(P[:, 0], P[:, 1], c=sd, cmap=cmap, norm=norm, s=4 if thumbnail else 8)
        ax.set_aspect("equal")
        if not thumbnail:
            ax.set_xlabel("x [m]")
            ax.set_ylabel("y [m]")
        axes.append(ax)
    else:
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # start-up: matplotlib kept out of explore3d --help's

        V, F = np.asarray(estimate.vertices, dtype=float), np.asarray(estimate.faces)
        face_sd = sd[F].mean(axis=1)
        lo = np.minimum(V.min(0), truth.bounds[0])
        hi = np.maximum(V.max(0), truth.bounds[1])
        c, r = (lo + hi) / 2.0, float((hi - lo).max()) / 2.0
        from mpl_toolkits.mplot3d.art3d import Line3DCollection  # start-up: matplotlib kept out of explore3d --help's

        sharp = truth.face_adjacency_angles > np.radians(TRUTH_EDGE_ANGLE_DEG)
        edges = truth.vertices[truth.face_adjacency_edges[sharp]]  # (k, 2, 3): the truth's outline
        for i, (elev, azim) in enumerate(views):
            ax = fig.add_subplot(1, n, i + 1, projection="3d")
            ax.add_collection3d(Poly3DCollection(V[F], facecolors=cmap(norm(face_sd)), edgecolors="none"))
            if len(edges):
                ax.add_collection3d(Line3DCollection(edges, colors="0.25", linewidths=0.6))
            ax.set_xlim(c[0] - r, c[0] + r)
            ax.set_ylim(c[1] - r, c[1] + r)
            ax.set_zlim(c[2] - r, c[2] + r)
            ax.set_box_aspect((1, 1, 1))
            ax.view_init(elev=elev, azim=azim)
            if thumbnail:
                ax.set_axis_off()
            else:
                ax.tick_params(labelsize=6)
                ax.locator_params(nbins=4)
            axes.append(ax)
    sm = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
    cb = fig.colorbar(sm, ax=axes, shrink=0.8, extend="both", pad=0.08 if not planar else 0.04)
    cb.set_label("signed distance [mm]" if thumbnail else "signed distance to the true surface [mm] (+ outside)",
                 fontsize=7 if thumbnail else 9)
    cb.ax.tick_params(labelsize=6 if thumbnail else 8)
    if title or not thumbnail:
        fig.suptitle(title or "estimate coloured by its signed distance to the truth",
                     fontsize=8 if thumbnail else 11)
    return _save(fig, path)


def run_pictures(out, exploration, estimate, truth, mesh, err) -> list[str]:
    """All pictures of a ``run`` into folder ``out``; returns their file names.

    Args:
        estimate, truth: shapely polygons (planar) or trimesh meshes (3d), metres, world frame.
        mesh: the object mesh (for the rendered scene).
        err: the :class:`ShapeError` of ``estimate``.
    """
    out = Path(out)
    numbers = {"error %": err.percent, "IoU": err.iou, "chamfer mm": 1e3 * err.chamfer_m,
               "hausdorff mm": 1e3 * err.hausdorff_m, "wraps": exploration.n_wraps,
               "points": len(exploration.points), "contacts": exploration.n_contacts,
               "wall s": exploration.wall_s, "sim s": exploration.sim_time_s, "arm": exploration.spec.name,
               "links": exploration.spec.n_links}
    names = []
    scene = None
    last = next((w[-1] for w in exploration.attempts if len(w)), None)
    if last is not None:
        try:
            scene = scene_image(mesh, exploration.spec, last)
        except Exception as exc:  # pybullet errors are plain `error`; a picture is never worth a failed run
            logging.getLogger(__name__).warning("no rendered scene: %s", exc)
    if exploration.config.mode == "planar":
        planar_figure(exploration, estimate, truth, out / "figure.png", err=err)
        names.append("figure.png")
        overview_figure(out / "overview.png", numbers, points=exploration.points, scene=scene,
                        estimate_polygon=estimate, truth_polygon=truth)
    else:
        views_figure(estimate, truth, out / "views.png", points=exploration.points, err=err)
        names.append("views.png")
        overview_figure(out / "overview.png", numbers, estimate_mesh=estimate, truth_mesh=truth,
                        points=exploration.points, scene=scene)
    names.append("overview.png")
    signed_distance_figure(estimate, truth, out / "signed_distance.png", title=f"signed distance{_err_title(err)}")
    names.append("signed_distance.png")
    if scene is not None:
        import matplotlib.image as mpimg  # start-up: matplotlib kept out of explore3d --help's

        with atomic_path(out / "scene.png") as tmp:
            mpimg.imsave(tmp, scene, format="png")
        names.append("scene.png")
    return names
