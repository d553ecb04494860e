"""A 3D recording of a run for the rerun viewer (``explore3d run ... --rerun run.rrd``, then
``rerun run.rrd``): the optional ``viz`` extra (``pip install -e ".[viz]"``, rerun-sdk).

:func:`write_rerun` writes one ``.rrd`` file from a finished run's
:class:`~explore3d.app.pipeline.Result`.  World frame, metres (the recording's world is right-handed,
z up); one sequence timeline ``wrap`` (the wrap index, 0-based, in the order the wraps ran: the
planned wraps, then the top search and the rounds of probes).  Entities:

* ``world/truth`` (static): the true object, grey mesh (evaluation only: the robot never sees it).
* ``world/estimate``: the estimate mesh after each round (logged at the round's last wrap: the
  planned wraps, each round of probes; the last is the run's estimate).  The earlier rounds'
  estimates are rebuilt from the contacts and swept space of their wraps as the pipeline builds the
  final one (3D runs; planar runs: the final estimate only, extruded as ``estimate.obj`` is).
* ``world/arm/links``: at each wrap, the links of its last attempt at its end (boxes
  ``link_length x link_width x link_height``, orange and blue in turn as in the URDF);
  ``world/arm/earlier_attempts`` the links of its earlier attempts (wireframe);
  ``world/arm/base`` the base block of each attempt.
* ``world/detections/wrap_NNN``: each detected contact of wrap NNN: the position of the joint whose
  sweep detected it, at the settled reading it was localised from (orange points).
* ``world/contacts/wrap_NNN``: the hull's input points of wrap NNN (what points.ply holds), coloured
  by :attr:`RecordingConfig.colour_by` (see :func:`contact_colours`), with each point's
  ``force_n``, ``uncertainty_m`` and ``link`` as extra values when they are localised contacts;
  ``world/contact_normals/wrap_NNN`` their normals (arrows of 5 mm, pointing out of the object).
* ``world/contacts_unused/wrap_NNN``: the localised contacts left out of the hull (too uncertain,
  unsettled, the arm touching itself; grey).
* ``world/free_space/wrap_NNN``: the space the wrap's links swept through
  (:class:`~explore3d.reconstruction.freespace.SweptArea`, what carves the hull), as points on the
  mid-plane of each swept slab every :attr:`RecordingConfig.free_space_step_m` metres (translucent blue).
* ``legend`` (static): this list, the colour scale and the units as a Markdown text.

Per-wrap entities accumulate: at wrap k the viewer shows every contact and all free space up to k.
"""
from __future__ import annotations

import dataclasses
import math
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from matplotlib import colormaps
from scipy.spatial.transform import Rotation

from explore3d.app.pipeline import Result, estimate_mesh, reconstruct_exploration
from explore3d.arm.kinematics import link_transforms
from explore3d.arm.spec import BASE_GAP_M
from explore3d.core.defaults import DEFAULT_A
from explore3d.core.interrupt import check_interrupt, import_optional
from explore3d.core.io import atomic_path
from explore3d.reconstruction.carve import DEFAULT_FIN_M, carve
from explore3d.reconstruction.tabletop import cut_at_table
from explore3d.strategy.explore import hulled_contacts

__all__ = ["COLOUR_BY", "RecordingConfig", "VIZ_FIX", "check_recording_path", "contact_colours", "require_rerun",
           "write_rerun"]

#: What the contact points may be coloured by.
COLOUR_BY = ("force", "uncertainty")

#: How to get the optional extra (the one line a missing rerun-sdk is refused with).
VIZ_FIX = 'pip install -e ".[viz]"'

_GREY = (150, 150, 150)
_LINK_COLOURS = ((242, 140, 26), (51, 115, 217))  # the URDF's link_a and link_b materials
_DETECTION = (255, 120, 0)
_FREE = (90, 160, 255, 70)
_NORMAL_LENGTH_M = 5.0e-3


@dataclass(frozen=True)
class RecordingConfig:
    """What :func:`write_rerun` records.

    Attributes:
        colour_by: the contact points' colour: ``force`` (the contact force, N) or ``uncertainty``
            (the position uncertainty along the link, m); see :func:`contact_colours`.
        rounds: also rebuild and record the estimate after each earlier round (3D; False: the
            final estimate only, at the last wrap).
        free_space_step_m: spacing of the free-space points, m (the swept pixels are 1 mm; every
            k-th in both directions is kept so the file stays small).
        point_radius_m: radius of the contact and detection points, m.
        name: the recording's name in the viewer.
    """

    colour_by: str = "force"
    rounds: bool = True
    free_space_step_m: float = 4.0e-3
    point_radius_m: float = 1.5e-3
    name: str = "explore3d run"

    def __post_init__(self):
        if self.colour_by not in COLOUR_BY:
            raise ValueError(f"colour_by must be one of {', '.join(COLOUR_BY)}; got {self.colour_by!r}")
        if not isinstance(self.rounds, bool):
            raise ValueError(f"rounds must be True or False; got {self.rounds!r}")
        for name in ("free_space_step_m", "point_radius_m"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of metres; got {v!r}")


def require_rerun():
    """``import rerun`` (the optional ``viz`` extra); ValueError naming the fix when it is missing.
    An interrupted import raises KeyboardInterrupt (:func:`~explore3d.core.interrupt.import_optional`)."""
    try:
        return import_optional("rerun")  # optional extra: viz (rerun-sdk)
    except (ImportError, OSError) as exc:
        raise ValueError(f"--rerun needs rerun-sdk, which cannot be imported ({exc}): {VIZ_FIX}, "
                         "or drop --rerun") from None


def check_recording_path(path, out=None) -> Path:
    """The recording's path, checked before any simulation: suffix ``.rrd``, not a folder, and its
    folder exists (or is the run's output folder ``out``, which the run creates).

    Raises:
        ValueError: the suffix is not .rrd, or the path is a folder.
        FileNotFoundError: its folder does not exist (message names the fix)."""
    p = Path(path)
    if p.suffix.lower() != ".rrd":
        raise ValueError(f"--rerun writes a rerun recording: give a file name ending in .rrd (e.g. run.rrd); got {str(path)!r}")
    if p.is_dir():
        raise ValueError(f"--rerun {str(path)!r} is a folder; give a file name ending in .rrd inside it")
    parent = p.parent
    if not parent.is_dir() and not (out is not None and parent.resolve() == Path(out).resolve()):
        raise FileNotFoundError(f"the folder of --rerun {str(path)!r} does not exist; create {str(parent)!r} first "
                                "or write the recording into --out")
    return p


def contact_colours(values, colour_by: str = "force") -> tuple[np.ndarray, float]:
    """(m, 3) uint8 sRGB colours of the contact points and the top of the scale.

    The scale is matplotlib's viridis from 0 (dark purple) to the run's largest value (yellow):
    force in N (``colour_by="force"``), or position uncertainty along the link in m
    (``"uncertainty"``).  NaN values (not known) are grey.  ``values`` (m,)."""
    v = np.asarray(values, dtype=float).reshape(-1)
    finite = np.isfinite(v)
    top = float(v[finite].max()) if finite.any() else 0.0
    top = top if top > 0 else 1.0
    rgb = (colormaps["viridis"](np.clip(np.where(finite, v, 0.0) / top, 0.0, 1.0))[:, :3] * 255).round()
    rgb[~finite] = _GREY
    return rgb.astype(np.uint8), top


# --- what is logged, as plain arrays (pure, no rerun) --------------------------------------------------

def _hull_contacts(ex):
    """The localised contacts behind ``ex.points`` (same order), or None (link points, or they
    do not match)."""
    if ex.config.points != "contacts" or ex.contacts is None:
        return None
    used = ex.contacts.select(ex.contacts.used)
    return used if len(used) == len(ex.points) else None


def _points3d(ex, z: float) -> np.ndarray:
    """(m, 3) the hull's input points, world frame, m (planar runs' 2D points at the plane's z)."""
    P = np.asarray(ex.points, dtype=float)
    if P.ndim == 2 and P.shape[1] == 3:
        return P
    P = P.reshape(-1, 2)
    return np.column_stack([P, np.full(len(P), z)])


def _quaternions(R) -> np.ndarray:
    """(k, 4) x, y, z, w of rotation matrices (k, 3, 3)."""
    return Rotation.from_matrix(np.asarray(R, dtype=float).reshape(-1, 3, 3)).as_quat()


def link_boxes(spec, q, T_world_base) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The links at angles ``q`` (n,) rad on the base pose ``T_world_base`` (4, 4): centres (n, 3)
    m and quaternions (n, 4) x, y, z, w, world frame, and half sizes (n, 3) m.  A link's box spans
    x in [0, link_length] of its frame (origin at its joint), y and z centred."""
    T = link_transforms(spec, q, T_world_base)
    centres = T[:, :3, 3] + T[:, :3, 0] * (spec.link_length / 2)
    half = np.tile([spec.link_length / 2, spec.link_width / 2, spec.link_height / 2], (len(T), 1))
    return centres, _quaternions(T[:, :3, :3]), half


def base_box(spec, T_world_base) -> tuple[np.ndarray, np.ndarray, float]:
    """The base block (as in the URDF): centre (3,) m, quaternion (4,), half size m."""
    T = np.asarray(T_world_base, dtype=float)
    b = spec.base_size
    return T[:3, 3] + T[:3, 0] * (-b / 2 - BASE_GAP_M), _quaternions(T[:3, :3])[0], b / 2


def _same_pose(A, B) -> bool:
    return bool(np.allclose(A, B, atol=1e-9))


def swept_wraps(ex) -> np.ndarray:
    """(len(ex.swept),) int: the wrap each swept area belongs to (by its base pose: the first wrap,
    from the previous area's on, with an attempt on that pose; the swept areas are in wrap order)."""
    bases = [[np.asarray(a.T_world_base, dtype=float) for a in w] for w in ex.attempts]
    out, w = [], 0
    for area in ex.swept:
        T = np.asarray(area.T_world_base, dtype=float)
        for k in list(range(w, len(bases))) + list(range(0, w)):
            if any(_same_pose(T, B) for B in bases[k]):
                w = k
                break
        out.append(w)
    return np.array(out, dtype=int)


def free_space_points(areas, step_m: float) -> np.ndarray:
    """(k, 3) world points, m: the centres of the free pixels of ``areas``
    (:class:`~explore3d.reconstruction.freespace.SweptArea`) on each slab's mid-plane, every
    ``step_m`` metres (rounded to whole pixels), duplicates dropped."""
    blocks = []
    for a in areas:
        s = max(1, int(round(step_m / a.pixel_m)))
        free = np.asarray(a.free, dtype=bool)
        i, j = np.nonzero(free[::s, ::s])
        if not len(i):
            continue
        xy = np.asarray(a.origin_m, dtype=float) + np.column_stack([i, j]) * s * a.pixel_m
        T = np.asarray(a.T_world_base, dtype=float)
        blocks.append(xy @ T[:3, :2].T + T[:3, 3])
    if not blocks:
        return np.zeros((0, 3))
    P = np.vstack(blocks)
    _, keep = np.unique(np.round(P / 1e-5).astype(np.int64), axis=0, return_index=True)
    return P[np.sort(keep)]


def round_ends(ex) -> list[tuple[str, int]]:
    """(name, k) for each round: the estimate after the first k wraps.  The planned wraps (with
    the top search) first, then each round of probes; the last k is ``ex.n_wraps``."""
    n = ex.n_wraps
    k = n - sum(int(r.get("wraps", 0)) for r in ex.probe_rounds)
    out = [("planned wraps", k)]
    for i, r in enumerate(ex.probe_rounds, 1):
        k += int(r.get("wraps", 0))
        if k == out[-1][1]:  # a round that added no wrap: the same estimate
            out.pop()
        out.append((f"probe round {i}", k))
    out[-1] = (out[-1][0], n)
    return [(name, k) for name, k in out if k > 0]


def prefix_estimate(result: Result, k: int, a: float = DEFAULT_A, method: str = "exponential"):
    """The 3D estimate the run had after its first ``k`` wraps: the hulled contacts of those
    wraps (:func:`~explore3d.strategy.explore.hulled_contacts`, chosen again over them alone), or
    their link points, their inverse hull carved by those wraps' swept space and cut at the
    table, as :func:`~explore3d.app.pipeline.estimate_exploration` builds the final one (wraps
    carried back after a motion stay as the run carried them).  Before the last wrap the carving's
    fins are kept, as in the estimate the probe rounds aimed at
    (:func:`explore3d.strategy.explore.current_estimate`); after it they are trimmed, as in the
    run's own (:func:`explore3d.reconstruction.carve.trim_fins`).  Closed trimesh, world frame, m.

    Raises:
        ValueError: those wraps give no hull."""
    ex = result.exploration
    config = ex.config
    centre, radius = result.centre, result.radius
    if config.points == "contacts" and ex.contacts is not None:
        cs = hulled_contacts(ex.contacts.select(ex.contacts.wrap < k), config, centre, radius, ex.poses, ex.table_z)
        used = cs.select(cs.used)
        points, pw, pa, pl = used.points, used.wrap, used.attempt, used.link
    else:
        keep = ex.point_wrap < k
        points, pw, pa, pl = ex.points[keep], ex.point_wrap[keep], ex.point_attempt[keep], ex.point_link[keep]
    wraps = swept_wraps(ex)
    swept = tuple(s for s, w in zip(ex.swept, wraps) if w < k)
    prefix = dataclasses.replace(ex, poses=ex.poses[:k], attempts=ex.attempts[:k], points=points, point_wrap=pw,
                                 point_attempt=pa, point_link=pl, swept=swept)
    hull = reconstruct_exploration(prefix, centre, radius, a=a, method=method)
    fin_m = DEFAULT_FIN_M if k >= ex.n_wraps else 0.0
    est = carve(hull.mesh, swept, fin_m=fin_m).mesh if config.free_space else hull.mesh
    return est if ex.table_z is None else cut_at_table(est, ex.table_z)


def _legend(result: Result, config: RecordingConfig, top: float | None) -> str:
    ex = result.exploration
    if top is None:
        scale = "the hull's input points are link face points (`--points links`): one colour (orange)"
    elif config.colour_by == "force":
        scale = f"viridis: 0 N (dark purple) to {top:.3g} N (yellow), the run's largest contact force"
    else:
        scale = (f"viridis: 0 mm (dark purple) to {top * 1e3:.3g} mm (yellow), the run's largest position "
                 "uncertainty along the link")
    return "\n".join([
        f"# explore3d run: {ex.n_wraps} wraps, {len(ex.points)} hull points",
        "",
        "World frame, metres, z up.  Timeline `wrap`: the wrap index (0-based) in the order the wraps ran.",
        "",
        "* `world/truth`: the true object (grey; evaluation only).",
        "* `world/estimate`: the estimate after each round (planned wraps, each round of probes), logged at "
        "the round's last wrap.",
        "* `world/arm/links`: the links of the wrap's last attempt at its end; `world/arm/earlier_attempts` "
        "its earlier attempts; `world/arm/base` the base block.",
        "* `world/detections/wrap_NNN`: where each contact was detected: the detecting joint at the settled reading.",
        f"* `world/contacts/wrap_NNN`: the hull's input points (points.ply); colour: {scale}.  Extra values: "
        "`force_n` (N), `uncertainty_m` (m), `link`.",
        "* `world/contact_normals/wrap_NNN`: their normals (5 mm arrows, out of the object).",
        "* `world/contacts_unused/wrap_NNN`: localised contacts left out of the hull (grey).",
        f"* `world/free_space/wrap_NNN`: the space the links swept through (points every "
        f"{config.free_space_step_m * 1e3:g} mm on the swept slab's mid-plane).",
    ]) + "\n"


# --- writing -------------------------------------------------------------------------------------

def _mesh(rr, mesh, rgba):
    """A closed trimesh (world frame, m) as rerun's Mesh3D of one colour ``rgba`` (0-255)."""
    return rr.Mesh3D(vertex_positions=np.asarray(mesh.vertices, dtype=np.float32),
                     triangle_indices=np.asarray(mesh.faces, dtype=np.uint32),
                     vertex_normals=np.asarray(mesh.vertex_normals, dtype=np.float32), albedo_factor=rgba)


def write_rerun(path, result: Result, truth=None, config: RecordingConfig = RecordingConfig(), *,
                a: float = DEFAULT_A, method: str = "exponential") -> Path:
    """Write ``result`` (a finished run) as a rerun recording to ``path`` (.rrd), atomically.

    Args:
        path: the .rrd file (its folder must exist; :func:`check_recording_path`).
        result: the run's :class:`~explore3d.app.pipeline.Result`.
        truth: the true object as a closed trimesh, world frame, m (default: ``result.truth`` in
            3D; planar runs, whose truth is a polygon, record it only when given).
        config: what to record (:class:`RecordingConfig`).
        a, method: the run's inverse-hull coarseness and method (to rebuild the earlier rounds'
            estimates as the run built its own).

    Returns:
        the path.  The entities, timeline and units are those of the module docstring; the
        contacts' colour scale is :func:`contact_colours`'.

    Raises:
        ValueError: rerun-sdk is missing (:func:`require_rerun`), ``path`` does not end in .rrd or
            is a folder, or ``config`` is not a :class:`RecordingConfig`.
        FileNotFoundError: the folder of ``path`` does not exist.
        OSError: the file cannot be written.
    """
    rr = require_rerun()
    if not isinstance(config, RecordingConfig):
        raise ValueError(f"config must be a RecordingConfig; got {type(config).__name__}")
    path = check_recording_path(path)
    ex = result.exploration
    spec = ex.spec
    planar = ex.config.mode == "planar"
    if truth is None and isinstance(result.truth, trimesh.Trimesh):
        truth = result.truth
    z_plane = float(np.asarray(result.centre, dtype=float)[2])
    P = _points3d(ex, z_plane)
    hulled = _hull_contacts(ex)
    if hulled is not None:
        values = hulled.force_n if config.colour_by == "force" else hulled.uncertainty_m
        colours, top = contact_colours(values, config.colour_by)
        if planar:
            P = np.asarray(hulled.points, dtype=float)
    else:
        colours, top = np.tile(np.array(_LINK_COLOURS[0], dtype=np.uint8), (len(P), 1)), None
    # the localised contacts left out of the hull (every one of them when the hull took link points)
    unused = None if ex.contacts is None or (hulled is None and ex.config.points == "contacts") else \
        ex.contacts.select(~ex.contacts.used)
    areas_wrap = swept_wraps(ex)
    estimates = {}  # wrap index -> (round name, k, mesh)
    ends = round_ends(ex)
    for name, k in ends:
        if k == ex.n_wraps:
            estimates[k - 1] = (name, k, estimate_mesh(result))
        elif config.rounds and not planar:
            check_interrupt()
            try:
                estimates[k - 1] = (name, k, prefix_estimate(result, k, a=a, method=method))
            except ValueError:  # too few contacts yet for a hull: nothing to show for that round
                pass

    path = Path(path)
    with atomic_path(path) as tmp:
        rec = rr.RecordingStream("explore3d", recording_id=uuid.uuid4())
        rec.save(tmp)
        rec.set_log_time_enabled(False)
        rec.set_log_tick_enabled(False)

        def log(entity, *parts, static=False):
            rec.log(entity, *parts, static=static, strict=True)

        with rec:  # its end finalises the file (the footer)
            rec.send_recording_name(config.name)
            log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
            log("legend", rr.TextDocument(_legend(result, config, top), media_type="text/markdown"), static=True)
            if truth is not None:
                log("world/truth", _mesh(rr, truth, (160, 160, 160, 110)), static=True)
            for w, attempts in enumerate(ex.attempts):
                check_interrupt()
                rec.set_time("wrap", sequence=w)
                boxes = [link_boxes(spec, att.q, att.T_world_base) for att in attempts]
                if boxes:
                    c, q_, h = boxes[-1]
                    log("world/arm/links", rr.Boxes3D(centers=c, half_sizes=h, quaternions=q_, fill_mode="solid",
                                                      colors=[_LINK_COLOURS[i % 2] for i in range(len(c))]))
                    bases = [base_box(spec, att.T_world_base) for att in attempts]
                    log("world/arm/base", rr.Boxes3D(centers=[b[0] for b in bases], quaternions=[b[1] for b in bases],
                                                     half_sizes=[[b[2]] * 3 for b in bases], colors=(77, 77, 77),
                                                     fill_mode="solid"))
                if len(boxes) > 1:
                    c = np.vstack([b[0] for b in boxes[:-1]])
                    log("world/arm/earlier_attempts", rr.Boxes3D(centers=c, half_sizes=np.vstack([b[2] for b in boxes[:-1]]),
                                                                 quaternions=np.vstack([b[1] for b in boxes[:-1]]),
                                                                 colors=_GREY, fill_mode="majorwireframe"))
                else:
                    log("world/arm/earlier_attempts", rr.Clear(recursive=False))
                det, joint = [], []
                for att in attempts:
                    for m in att.moments:
                        T = link_transforms(spec, m.reading.q, att.T_world_base)
                        det.append(T[m.joint, :3, 3])
                        joint.append(int(m.joint))
                if det:
                    log(f"world/detections/wrap_{w:03d}",
                        rr.Points3D(np.array(det), radii=config.point_radius_m, colors=_DETECTION),
                        rr.AnyValues(joint=np.array(joint, dtype=np.int64)))
                mine = np.asarray(ex.point_wrap) == w
                if mine.any():
                    extra = []
                    if hulled is not None:
                        sel = hulled.select(mine)
                        extra = [rr.AnyValues(force_n=sel.force_n, uncertainty_m=sel.uncertainty_m,
                                              link=sel.link.astype(np.int64))]
                        normals = np.asarray(sel.normals, dtype=float)
                        log(f"world/contact_normals/wrap_{w:03d}",
                            rr.Arrows3D(origins=P[mine], vectors=normals * _NORMAL_LENGTH_M, colors=colours[mine]))
                    log(f"world/contacts/wrap_{w:03d}",
                        rr.Points3D(P[mine], radii=config.point_radius_m, colors=colours[mine]), *extra)
                if unused is not None and (unused.wrap == w).any():
                    sel = unused.select(unused.wrap == w)
                    log(f"world/contacts_unused/wrap_{w:03d}",
                        rr.Points3D(sel.points, radii=config.point_radius_m * 0.7, colors=_GREY),
                        rr.AnyValues(force_n=sel.force_n, uncertainty_m=sel.uncertainty_m))
                F = free_space_points([s for s, sw in zip(ex.swept, areas_wrap) if sw == w], config.free_space_step_m)
                if len(F):
                    log(f"world/free_space/wrap_{w:03d}",
                        rr.Points3D(F, radii=config.free_space_step_m / 2, colors=_FREE))
                if w in estimates:
                    name, k, mesh = estimates[w]
                    log("world/estimate", _mesh(rr, mesh, (60, 180, 90, 255)),
                        rr.AnyValues(round=name, wraps=k, volume_m3=float(abs(mesh.volume))))
        del rec
    return path
