"""Where the arm's base goes for each wrap: pure functions returning known base transforms.

A *wrap frame* W is placed at a point on the object's rough centre line: z_W is the wrap plane's
normal, the arm lies in the plane z_W = 0 and curls towards +y.  The base sits so that the straight
arm (along +x from the base) passes ``clearance`` metres outside the rough bounding circle of
radius ``r`` centred ``(x_c, y_c)`` in the base frame.  The robot knows only the rough centre
``centre`` (3,) and bounding radius ``radius`` of the object, never its mesh.

``T_world_base`` (4, 4) maps base coordinates to world coordinates.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from explore3d.core.validate import check_positive, check_vector


@dataclass(frozen=True)
class WrapPose:
    """One wrap: its base transform and where it came from.

    Attributes:
        T_world_base: (4, 4) base pose, world frame.
        normal: (3,) the wrap plane's unit normal, world frame.
        offset: signed distance of the plane from the rough centre along ``normal``, metres.
        angle: rotation of the approach about ``normal``, rad.
        label: a short human-readable name.
    """

    T_world_base: np.ndarray
    normal: np.ndarray
    offset: float
    angle: float
    label: str


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def frame_from_normal(normal) -> np.ndarray:
    """(3, 3) rotation whose z column is ``normal`` (3,) and whose x column is a fixed,
    deterministic perpendicular (world x projected, or world y when normal is near x)."""
    n = check_vector(normal, "normal", 3)
    n = n / np.linalg.norm(n)
    ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = ref - n * (ref @ n)
    x /= np.linalg.norm(x)
    y = np.cross(n, x)
    return np.stack([x, y, n], axis=1)


def base_in_wrap_frame(r: float, arm_width: float, clearance: float, lead: float) -> np.ndarray:
    """(4, 4) ``T_wrap_base``: the wrap frame's origin is the rough centre; the base sits at
    (-lead, -(r + clearance + arm_width / 2)) so the straight arm along +x clears the bounding
    circle of radius ``r`` by ``clearance`` and the centre lies ``lead`` metres along the arm."""
    T = np.eye(4)
    T[:3, 3] = [-lead, -(r + clearance + arm_width / 2.0), 0.0]
    return T


def wrap_pose(centre, R_world_wrap, offset: float, r: float, arm_width: float, clearance: float, lead: float,
              normal, angle: float, label: str) -> WrapPose:
    T_world_wrap = np.eye(4)
    T_world_wrap[:3, :3] = R_world_wrap
    T_world_wrap[:3, 3] = np.asarray(centre, float) + offset * np.asarray(normal, float)
    return WrapPose(T_world_wrap @ base_in_wrap_frame(r, arm_width, clearance, lead), np.asarray(normal, float),
                    float(offset), float(angle), label)


def planar_directions(n_directions: int, mirrored: bool = False) -> list[tuple[float, bool]]:
    """Approach directions of the planar case as (angle about +z, rad; mirrored?) pairs.

    ``mirrored=True`` with 2 directions is the paper's second direction: the first motion seen in
    a mirror through the object's centre (realised rigidly by turning the arm over, which a planar
    arm with gravity along its joint axes cannot tell apart).  Otherwise directions are 90 degrees
    apart for up to four (the paper recommends three), evenly spread beyond.
    """
    if not isinstance(n_directions, int) or n_directions < 1:
        raise ValueError(f"n_directions must be an integer >= 1; got {n_directions!r}")
    if mirrored:
        if n_directions != 2:
            raise ValueError(f"mirrored directions come as a pair; got n_directions={n_directions}")
        return [(0.0, False), (0.0, True)]
    step = math.pi / 2 if n_directions <= 4 else 2 * math.pi / n_directions
    return [(i * step, False) for i in range(n_directions)]


def planar_wrap_poses(centre, radius: float, arm_width: float, n_directions: int = 3, mirrored: bool = False,
                      clearance: float = 0.01, lead: float | None = None) -> list[WrapPose]:
    """Base poses for the planar case: the arm in the world x-y plane through ``centre`` (3,)."""
    centre = check_vector(centre, "centre", 3)
    r = check_positive(radius, "radius")
    lead = r if lead is None else lead
    out = []
    z = np.array([0.0, 0.0, 1.0])
    for angle, mirror in planar_directions(n_directions, mirrored):
        R = _rot_z(angle)
        if mirror:  # turn the arm over about the wrap frame's y axis: x -> -x, z -> -z
            R = R @ np.diag([-1.0, 1.0, -1.0])
        label = f"{math.degrees(angle):.0f}deg" + (" mirrored" if mirror else "")
        out.append(wrap_pose(centre, R, 0.0, r, arm_width, clearance, lead, z, angle, label))
    return out


def fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere (golden-angle spiral), deterministic."""
    if n < 1:
        raise ValueError(f"need at least one direction; got {n}")
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    rho = np.sqrt(1.0 - z * z)
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)


def spatial_wrap_poses(centre, radius: float, arm_width: float, n_normals: int = 24, n_offsets: int = 3,
                       n_angles: int = 2, offset_span: float = 0.7, clearance: float = 0.01,
                       lead: float | None = None) -> list[WrapPose]:
    """Base poses for 3D: wrap planes with normals spread over the sphere, each at ``n_offsets``
    offsets along its normal in [-offset_span, offset_span] x ``radius``, approached from
    ``n_angles`` directions evenly spaced about the normal.

    Each plane's in-plane bound is ``sqrt(radius^2 - offset^2)``; the base is placed for it.
    Returns n_normals * n_offsets * n_angles poses in a fixed order.
    """
    centre = check_vector(centre, "centre", 3)
    R_b = check_positive(radius, "radius")
    offsets = np.zeros(1) if n_offsets == 1 else np.linspace(-offset_span, offset_span, n_offsets) * R_b
    out = []
    for i, n in enumerate(fibonacci_sphere(n_normals)):
        R0 = frame_from_normal(n)
        for s in offsets:
            r = math.sqrt(max(R_b * R_b - s * s, (0.2 * R_b) ** 2))
            for a_i in range(n_angles):
                # stagger the approach angle from normal to normal so the set covers all angles
                angle = 2 * math.pi * (a_i + 0.5 * (i % 2)) / n_angles
                R = R0 @ _rot_z(angle)
                ld = r if lead is None else lead
                out.append(wrap_pose(centre, R, float(s), r, arm_width, clearance, ld, n, angle,
                                     f"n{i} s{s * 1000:+.0f}mm a{math.degrees(angle):.0f}deg"))
    return out


def horizontal_wrap_pose(centre, radius: float, arm_width: float, table_z: float, z: float, angle: float,
                         up: bool = True, clearance: float = 0.01, lead: float | None = None,
                         label: str = "table") -> WrapPose:
    """The base pose of a horizontal wrap at world height ``z`` (m) around the rough centre (3,)
    of bounding radius ``radius`` (m), approached from ``angle`` (rad about +z), the curl turning
    anticlockwise seen from above (``up``: plane normal +z) or clockwise (-z).  The plane's
    in-plane bound is ``sqrt(radius^2 - s^2)`` (``s`` its height over the centre), at least
    0.2 ``radius``.  Labelled ``"<label> z+Hmm aAdeg[ cw]"`` with H the height over ``table_z``."""
    s = float(z - centre[2])
    r = math.sqrt(max(radius * radius - s * s, (0.2 * radius) ** 2))
    n = np.array([0.0, 0.0, 1.0 if up else -1.0])
    R = frame_from_normal(n) @ _rot_z(angle)
    ld = r if lead is None else lead
    return wrap_pose(centre, R, s if up else -s, r, arm_width, clearance, ld, n, angle,
                     f"{label} z{(z - table_z) * 1000:+.0f}mm a{math.degrees(angle):.0f}deg{'' if up else ' cw'}")


def table_wrap_poses(centre, radius: float, arm_width: float, table_z: float, lowest_m: float,
                     n_heights: int = 5, n_angles: int = 8, n_normals: int = 48, n_tilted_angles: int = 2,
                     clearance: float = 0.01, lead: float | None = None) -> list[WrapPose]:
    """Base poses for an object resting on a table whose top is at world z ``table_z`` (m).

    Horizontal wraps (the paper's setting) at ``n_heights`` heights from ``table_z + lowest_m`` (the
    lowest plane the arm and its base block fit above the table) up to the rough centre's height
    plus 0.7 ``radius``, each approached from ``n_angles`` directions about the vertical, the
    curl turning alternately anticlockwise and clockwise (plane normal +z, -z); then the tilted
    wraps of :func:`spatial_wrap_poses` (``n_normals`` x ``n_tilted_angles``, planes through the
    rough centre) whose normal is more than 10 degrees from the vertical.  The caller keeps those
    whose start clears the table (:func:`explore3d.arm.workspace.pose_clears`) and stops each sweep at
    the floor (:func:`explore3d.arm.workspace.floor_stop`).

    Args:
        centre: (3,) the rough centre, world frame, m; radius: the rough bounding radius, m.
        lowest_m: height of the lowest horizontal plane above the table, m.
    """
    centre = check_vector(centre, "centre", 3)
    R_b = check_positive(radius, "radius")
    z_lo = float(table_z) + float(lowest_m)
    z_hi = float(centre[2]) + 0.7 * R_b
    if z_hi < z_lo:
        z_hi = z_lo
    heights = np.linspace(z_lo, z_hi, n_heights) if n_heights > 1 else np.array([z_lo])
    out = []
    for h_i, z in enumerate(heights):
        for a_i in range(n_angles):
            out.append(horizontal_wrap_pose(centre, R_b, arm_width, table_z, float(z),
                                            2 * math.pi * (a_i + 0.5 * (h_i % 2)) / n_angles, (a_i + h_i) % 2 == 0,
                                            clearance, lead))
    for p in spatial_wrap_poses(centre, R_b, arm_width, n_normals, 1, n_tilted_angles, clearance=clearance, lead=lead):
        if abs(p.normal[2]) < math.cos(math.radians(10.0)):
            out.append(p)
    return out
