"""Pictures of an exploration (matplotlib, Agg backend: no display needed; PNG files, atomic).

* :func:`planar_figure`: the paper's figure style: the arm (joint positions) and the points
  (localised contacts, or the paper's link points: :func:`points_label`) of each attempt coloured
  by wrap, the generated polygon over the true one, a legend and the percent error in the title.
* :func:`views_figure`: estimate (blue, translucent) over truth (grey fill, its outline in black
  on top) and the points (red) from several view directions, axes in mm, a legend.
* :func:`scene_image`: PyBullet's TinyRenderer (DIRECT client, no GUI) of the truth mesh and the
  arm at one attempt's final joint angles, the camera (:func:`scene_camera`) framing both.
* :func:`overview_figure`: one page with views and the numbers.
* :func:`signed_distance_figure`: the estimate coloured by its signed distance to the truth, mm
  (:func:`signed_distance_mm`; positive outside the truth: where the estimate is too big), a
  diverging colormap centred on 0 with a colorbar.

All coordinates are metres in the world frame (= the object's own frame); the 3D views' ticks show mm.
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
from explore3d.arm.spec import BASE_GAP_M
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


def points_label(config) -> str:
    """What an exploration's points are, for a legend: ``"contacts"`` (localised contacts, the
    default ``ExploreConfig.points``) or ``"link points"`` (the paper's, ``points="links"``)."""
    return "link points" if config.points == "links" else "contacts"


def planar_figure(exploration, estimate_polygon, truth_polygon, path, err=None, title: str = "") -> Path:
    """Paper-style planar figure (PNG) at ``path``; returns it.

    Args:
        exploration: an :class:`explore3d.strategy.explore.Exploration` in planar mode (points (m, 2),
            named in the legend by :func:`points_label` of its config).
        estimate_polygon, truth_polygon: shapely polygons, world x-y, metres.
        err: optional :class:`explore3d.geometry.metrics.ShapeError` for the title.
    """
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 6))
    cmap = plt.get_cmap("tab10")
    P = np.asarray(exploration.points)[:, :2]
    what = points_label(exploration.config)
    lines = arm_polylines(exploration)
    for w, rows in enumerate(lines):
        c = cmap(w % 10)
        for k, xy in enumerate(rows):
            ax.plot(xy[:, 0], xy[:, 1], "-o", color=c, ms=2.5, lw=1.0, alpha=0.45 + 0.55 * (k + 1) / len(rows),
                    label=f"wrap {w + 1}: arm" if k == 0 else None)
        sel = exploration.point_wrap == w
        ax.plot(P[sel, 0], P[sel, 1], ".", color=c, ms=3, label=f"wrap {w + 1}: {what}")
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
#: The axis each axis-aligned view looks along (its title says so): seen end-on, its tick labels
#: would pile up and its label would sit by another axis's (both are left out); these views are
#: drawn in orthographic projection.
END_ON = {"top": "z", "front": "y", "side": "x"}
END_ON_WORDS = {"top": "looking down -z", "front": "looking along +y", "side": "looking along -x"}

#: At most this many points are drawn in a 3D view (readability and file size).
MAX_DRAWN_POINTS = 3000
#: At most this many ticks per axis of a 3D view (more pile up into clumps).
MAX_TICKS_3D = 4

ESTIMATE_STYLE = {"color": "tab:blue", "alpha": 0.35, "edgecolor": (0.0, 0.0, 0.5, 0.4), "linewidth": 0.2}
TRUTH_FILL = {"color": "0.6", "alpha": 0.2}
TRUTH_LINE = {"color": "black", "linewidth": 0.9}
POINTS_COLOR = "crimson"


def _mm(value, _pos=None) -> str:
    """A tick label in mm of a coordinate in metres."""
    return f"{round(1e3 * value, 6) + 0.0:g}"


def _mm_axes_3d(ax, end_on: str | None = None) -> None:
    """x, y, z labels in mm (the coordinates are metres; the ticks show mm), at most
    :data:`MAX_TICKS_3D` ticks an axis; the axis ``end_on`` ("x", "y", "z") seen end-on has neither
    (and the view is orthographic)."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator, NullFormatter  # start-up: kept out of --help's

    for name in "xyz":
        axis = getattr(ax, f"{name}axis")
        axis.set_major_locator(MaxNLocator(MAX_TICKS_3D))
        axis.set_major_formatter(NullFormatter() if name == end_on else FuncFormatter(_mm))
        getattr(ax, f"set_{name}label")("" if name == end_on else f"{name} [mm]", fontsize=7, labelpad=2)
    ax.tick_params(labelsize=6, pad=0)
    if end_on:
        ax.set_proj_type("ortho")


def truth_lines(mesh, along: str | None = None) -> np.ndarray:
    """(k, 2, 3) segments, metres, drawn for the truth over the estimate: its edges sharper than
    :data:`TRUTH_EDGE_ANGLE_DEG` and its section by the plane through its bounding box's centre
    normal to the view direction ``along`` ("x", "y", "z": an outline a smooth surface lacks), or
    with ``along`` None and no sharp edge (a sphere), its sections normal to x, y and z."""
    sharp = mesh.face_adjacency_angles > np.radians(TRUTH_EDGE_ANGLE_DEG)
    segs = [np.asarray(mesh.vertices)[mesh.face_adjacency_edges[sharp]].reshape(-1, 2, 3)]
    centre = np.asarray(mesh.bounds, dtype=float).mean(axis=0)
    axes = "xyz" if along is None and not sharp.any() else (along or "")
    for a in axes:
        normal = np.eye(3)["xyz".index(a)]
        segs.append(np.asarray(trimesh.intersections.mesh_plane(mesh, normal, centre), dtype=float).reshape(-1, 2, 3))
    return np.concatenate(segs)


def _legend(fig, points_name: str | None) -> None:
    """The figure's legend: estimate, truth and (when drawn) the points named ``points_name``."""
    from matplotlib.lines import Line2D  # start-up: matplotlib kept out of explore3d --help's
    from matplotlib.patches import Patch  # start-up: as above

    handles = [Patch(facecolor=ESTIMATE_STYLE["color"], alpha=ESTIMATE_STYLE["alpha"] + 0.15,
                     edgecolor=ESTIMATE_STYLE["edgecolor"], label="estimate"),
               Patch(facecolor=(0.6, 0.6, 0.6, 0.3), edgecolor=TRUTH_LINE["color"], label="truth (outline in black)")]
    if points_name:
        handles.append(Line2D([], [], ls="", marker="o", ms=4, color=POINTS_COLOR, label=points_name))
    fig.legend(handles=handles, loc="upper center", ncol=len(handles), fontsize=9, frameon=False,
               bbox_to_anchor=(0.5, 0.955))


def _draw_mesh_views(fig, axes_slots, estimate_mesh, truth_mesh, points=None, points_name: str = "contacts"):
    """The :data:`VIEWS` of the meshes (and points) into subplots ``axes_slots`` of ``fig``, with the legend."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection  # start-up: matplotlib kept out of explore3d --help's

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
        ax.computed_zorder = False  # drawn in order: the truth's outline and the points over the estimate
        v, f = truth_mesh.vertices, truth_mesh.faces
        ax.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=f, linewidth=0, **TRUTH_FILL)
        v, f = estimate_mesh.vertices, estimate_mesh.faces
        ax.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=f, **ESTIMATE_STYLE)
        end_on = END_ON.get(name)
        outline = truth_lines(truth_mesh, end_on)
        if len(outline):
            ax.add_collection3d(Line3DCollection(outline, colors=TRUTH_LINE["color"],
                                                 linewidths=TRUTH_LINE["linewidth"]))
        if P is not None and len(P):
            ax.scatter(P[:, 0], P[:, 1], P[:, 2], s=2, color=POINTS_COLOR, alpha=0.6, depthshade=False)
        ax.set_xlim(c[0] - r, c[0] + r)
        ax.set_ylim(c[1] - r, c[1] + r)
        ax.set_zlim(c[2] - r, c[2] + r)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=elev, azim=azim)
        _mm_axes_3d(ax, end_on)
        ax.set_title(name if not end_on else f"{name} ({END_ON_WORDS[name]})", fontsize=9)
    _legend(fig, points_name if P is not None and len(P) else None)


def views_figure(estimate_mesh, truth_mesh, path, points=None, err=None, title: str = "",
                 points_name: str = "contacts") -> Path:
    """Estimate (blue) vs truth (grey, its outline black) meshes (trimesh, metres) from :data:`VIEWS`,
    axes in mm, with a legend; PNG at ``path``.  ``points``: optional (m, 3) points drawn in red,
    named ``points_name`` in the legend (:func:`points_label`)."""
    plt = _plt()
    fig = plt.figure(figsize=(10, 10))
    _draw_mesh_views(fig, [(2, 2, i + 1) for i in range(4)], estimate_mesh, truth_mesh, points, points_name)
    fig.suptitle((title or "estimate vs truth") + _err_title(err))
    return _save(fig, path)


#: The scene camera's vertical field of view, degrees, yaw and pitch, degrees (PyBullet's).
SCENE_FOV_DEG = 40.0
SCENE_YAW_DEG = 30.0
SCENE_PITCH_DEG = -35.0
#: The scene camera frames the object and the arm in its field of view narrowed this many times.
SCENE_MARGIN = 1.1


def scene_points(truth_mesh, spec, attempt) -> np.ndarray:
    """(k, 3) world points, metres, the scene camera frames: the corners of the truth mesh's bounding
    box and of the arm's base block, and the arm's joints and tip at ``attempt`` (padded by the
    links' half-size)."""
    T_base = np.asarray(attempt.T_world_base, dtype=float)
    T = link_transforms(spec, np.asarray(attempt.q, dtype=float), T_base)
    tip = T[-1] @ np.array([spec.link_length, 0.0, 0.0, 1.0])
    arm = np.vstack([T[:, :3, 3], tip[:3]])
    pad = 0.5 * max(spec.link_width, spec.link_height)
    b = spec.base_size
    block = _box_corners([-BASE_GAP_M - b, -b / 2, -b / 2], [-BASE_GAP_M, b / 2, b / 2])
    block = block @ T_base[:3, :3].T + T_base[:3, 3]
    return np.vstack([_box_corners(*truth_mesh.bounds), block, arm - pad, arm + pad])


def _box_corners(lo, hi) -> np.ndarray:
    """(8, 3) corners of the axis-aligned box [lo, hi]."""
    return np.stack(np.meshgrid(*zip(lo, hi), indexing="ij"), axis=-1).reshape(-1, 3).astype(float)


def scene_camera(truth_mesh, spec, attempt, width: int = 480, height: int = 360):
    """PyBullet's (view, projection) matrices (16 floats each, column-major) of :func:`scene_image`:
    from yaw :data:`SCENE_YAW_DEG` and pitch :data:`SCENE_PITCH_DEG`, at the nearest distance at
    which every one of :func:`scene_points` is in view (the field of view narrowed by
    :data:`SCENE_MARGIN`), centred on them: the object and the whole arm."""
    import pybullet as p  # start-up: kept out of explore3d --help's

    P = scene_points(truth_mesh, spec, attempt)
    target = (P.min(axis=0) + P.max(axis=0)) / 2.0
    ty = np.tan(np.radians(SCENE_FOV_DEG) / 2.0) / SCENE_MARGIN
    tx = ty * width / height
    for i in range(3):  # the distance that fits; twice the target moved to the middle of the view
        V1 = np.reshape(p.computeViewMatrixFromYawPitchRoll(target.tolist(), 1.0, SCENE_YAW_DEG, SCENE_PITCH_DEG,
                                                            0.0, 2), (4, 4), order="F")
        C = P @ V1[:3, :3].T + V1[:3, 3]  # camera frame at distance 1 (OpenGL: looking along -z)
        depth = -C[:, 2] - 1.0  # + the distance
        dist = float(np.max(np.maximum(np.abs(C[:, 0]) / tx, np.abs(C[:, 1]) / ty) - depth))
        dist = max(dist, float(np.max(-depth)) + 1e-2)  # every point in front of the camera
        if i == 2:
            break
        u, v = C[:, 0] / (tx * (dist + depth)), C[:, 1] / (ty * (dist + depth))  # in [-1, 1]: in view
        shift = np.array([(u.max() + u.min()) * tx, (v.max() + v.min()) * ty, 0.0]) * dist / 2.0
        target = target + V1[:3, :3].T @ shift
    view = p.computeViewMatrixFromYawPitchRoll(target.tolist(), dist, SCENE_YAW_DEG, SCENE_PITCH_DEG, 0.0, 2)
    near, far = max(0.5 * float(np.min(dist + depth)), 1e-3), 2.0 * float(np.max(dist + depth))
    proj = p.computeProjectionMatrixFOV(SCENE_FOV_DEG, width / height, near, far)
    return view, proj


def scene_image(truth_mesh, spec, attempt, width: int = 480, height: int = 360) -> np.ndarray:
    """(height, width, 3) uint8 RGB image from PyBullet's TinyRenderer (DIRECT client) of the truth
    mesh (metres, world frame) and the arm ``spec`` at ``attempt.q`` (rad) on ``attempt.T_world_base``,
    through :func:`scene_camera`."""
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
        view, proj = scene_camera(truth_mesh, spec, attempt, width, height)
        img = p.getCameraImage(width, height, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=cid)
    finally:
        p.disconnect(cid)
    rgba = np.reshape(np.asarray(img[2], dtype=np.uint8), (height, width, 4))
    return rgba[:, :, :3].copy()


def overview_figure(path, numbers: dict, estimate_mesh=None, truth_mesh=None, points=None, scene=None,
                    estimate_polygon=None, truth_polygon=None, title: str = "", points_name: str = "contacts") -> Path:
    """One-page overview PNG: views (3D meshes as in :func:`views_figure`, or the 2D polygons), an
    optional rendered scene ((h, w, 3) uint8) and a text panel of ``numbers`` (name -> value).
    ``points_name``: what ``points`` are, for the legend (:func:`points_label`)."""
    plt = _plt()
    fig = plt.figure(figsize=(12, 8))
    if estimate_mesh is not None:
        _draw_mesh_views(fig, [(2, 3, 1), (2, 3, 2), (2, 3, 4), (2, 3, 5)], estimate_mesh, truth_mesh, points,
                         points_name)
    elif estimate_polygon is not None:
        ax = fig.add_subplot(1, 3, (1, 2))
        for ring in _rings(truth_polygon):
            ax.fill(ring[:, 0], ring[:, 1], color="0.6", alpha=0.4, label="true shape")
        for ring in _rings(estimate_polygon):
            ax.plot(ring[:, 0], ring[:, 1], "-", color="crimson", lw=2, label="generated shape")
        if points is not None:
            P = np.asarray(points)
            ax.plot(P[:, 0], P[:, 1], ".", ms=2, color="tab:blue", label=points_name)
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
    degrees) with the truth's outline (edges sharper than :data:`TRUTH_EDGE_ANGLE_DEG`) in grey,
    axes in mm as in :func:`views_figure`.  Planar (shapely polygons): the estimate's boundary
    samples coloured, the truth's outline in grey.  ``thumbnail``: one small view (the sweep report's table).  A symmetric diverging scale
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
                _mm_axes_3d(ax, END_ON.get(dict(zip(VIEWS, VIEW_NAMES)).get((elev, azim))))
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
    what = points_label(exploration.config)
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
                        estimate_polygon=estimate, truth_polygon=truth, points_name=what)
    else:
        views_figure(estimate, truth, out / "views.png", points=exploration.points, err=err, points_name=what)
        names.append("views.png")
        overview_figure(out / "overview.png", numbers, estimate_mesh=estimate, truth_mesh=truth,
                        points=exploration.points, scene=scene, points_name=what)
    names.append("overview.png")
    signed_distance_figure(estimate, truth, out / "signed_distance.png", title=f"signed distance{_err_title(err)}")
    names.append("signed_distance.png")
    if scene is not None:
        import matplotlib.image as mpimg  # start-up: matplotlib kept out of explore3d --help's

        with atomic_path(out / "scene.png") as tmp:
            mpimg.imsave(tmp, scene, format="png")
        names.append("scene.png")
    return names
