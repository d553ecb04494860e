"""Contact-thickness calibration on a known object, the way a real arm would do it.

The faces of links that touched sit a systematic gap outside the object's surface (in PyBullet
mostly the 1 mm collision margin of the object mesh, :data:`explore3d.geometry.sdf.PYBULLET_MESH_MARGIN_M`,
plus the detection delay and the solver's compliance), so a reconstruction from link points
comes out too large.  A real arm calibrates this once: it explores an object whose shape and pose
it knows, measures how far its contact points lie outside that known surface, and from then on
pushes its faces inwards by that much (``ExploreConfig.face_offset``).

The calibration object is *never* the object under test.  The default is a sphere of radius
60 mm at the origin (:func:`calibration_sphere`):

* a precision ball is the standard calibration artefact: its surface is known from its centre
  and radius alone, so only the position of the fixture must be known, not its orientation;
* every wrap plane of the planar and the 3D modes meets it, so the same routine calibrates both;
* it is none of the evaluation objects (the 80 mm cube, the 63 mm cylinder, and the built-in
  50 mm ``sphere``): flat faces, a curve of 63 mm radius in the plane, and a doubly curved
  surface of 60 mm radius are different contact situations (face, line and point contact), so a
  gap that transfers from the ball to the cube and the cylinder is a property of the arm and the
  simulation, not of one shape.

The statistic: for each contact-flagged joint of each attempt, the contact link (the one of the
swept link and its distal links nearest the known surface), once per (attempt, link); the
smallest signed distance of that link's own points (as the exploration reports them, with
``face_offset = 0``) to the known surface.  Links farther than ``reject_m`` are not in contact
(false detections, see :mod:`explore3d.world.quality`) and are left out; the median of the rest is the
calibrated ``face_offset``.  Evaluation against the *true* object of a run lives in
:mod:`explore3d.world.quality`; here the only "truth" used is the known calibration object.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import asdict, dataclass

import numpy as np

from explore3d.core.validate import check_positive, check_vector
from explore3d.geometry.sdf import SignedDistance
from explore3d.strategy.explore import ExploreConfig
from explore3d.world.explore import explore
from explore3d.world.objects import CALIBRATION_SPHERE_RADIUS_M, calibration_sphere
from explore3d.world.quality import contact_point_gaps

__all__ = [
    "CALIBRATION_SPHERE_RADIUS_M",
    "REJECT_GAP_M",
    "ThicknessCalibration",
    "calibrate_thickness",
    "calibration_sphere",
    "thickness_from_gaps",
]


#: Contact links whose points are farther than this from the known surface are not in contact
#: (false detections) and do not enter the calibration, metres.  Twice PyBullet's 1 mm mesh
#: margin, the same tolerance as :data:`explore3d.world.quality.FALSE_DETECTION_TOL_M`.
REJECT_GAP_M = 2.0e-3


@dataclass(frozen=True)
class ThicknessCalibration:
    """A contact-thickness calibration (SI units).

    Attributes:
        face_offset_m: the calibrated thickness, metres: pass it as ``ExploreConfig.face_offset``.
            The median of the accepted gaps (a robust centre; 0 if there are none).
        gap_median_m, gap_mean_m, gap_p10_m, gap_p90_m: statistics of the accepted gaps, metres.
        n_points: number of accepted gaps (one per attempt and contact link).
        n_rejected: contact links farther than ``reject_m`` (left out).
        reject_m: the rejection distance, metres.
        object: a short description of the calibration object.
        n_wraps, steps: size of the calibration exploration.
        wall_s: wall-clock time of the calibration, s.
    """

    face_offset_m: float
    gap_median_m: float
    gap_mean_m: float
    gap_p10_m: float
    gap_p90_m: float
    n_points: int
    n_rejected: int
    reject_m: float
    object: str = ""
    n_wraps: int = 0
    steps: int = 0
    wall_s: float = 0.0

    def to_dict(self) -> dict:
        return asdict(self)




def thickness_from_gaps(gaps, reject_m: float = REJECT_GAP_M, object: str = "", n_wraps: int = 0,
                        steps: int = 0, wall_s: float = 0.0) -> ThicknessCalibration:
    """The calibration from measured contact gaps.

    Args:
        gaps: (m,) signed distances of contact points to the known surface, metres (positive
            outside).  Values above ``reject_m`` are left out (not in contact).
        reject_m: metres, > 0.

    Returns:
        A :class:`ThicknessCalibration` whose ``face_offset_m`` is the median accepted gap.
    """
    g = np.asarray(gaps, dtype=np.float64)
    if g.ndim != 1:
        raise ValueError(f"gaps must be a 1-D array of distances in metres; got shape {g.shape}")
    if not np.isfinite(g).all():
        raise ValueError("gaps must be finite; remove NaN/inf values first")
    reject = check_positive(reject_m, "reject_m")
    ok = g[g <= reject]
    if ok.size == 0:
        nan = float("nan")
        return ThicknessCalibration(0.0, nan, nan, nan, nan, 0, int(g.size), reject, object, n_wraps, steps, wall_s)
    med = float(np.median(ok))
    return ThicknessCalibration(
        face_offset_m=med, gap_median_m=med, gap_mean_m=float(ok.mean()), gap_p10_m=float(np.percentile(ok, 10)),
        gap_p90_m=float(np.percentile(ok, 90)), n_points=int(ok.size), n_rejected=int(g.size - ok.size),
        reject_m=reject, object=object, n_wraps=n_wraps, steps=steps, wall_s=wall_s)


def calibrate_thickness(arm="default", config=None, calibration_object=None, reject_m: float = REJECT_GAP_M,
                        label: str | None = None, progress=None) -> ThicknessCalibration:
    """Explore a known calibration object and return the contact thickness to apply.

    Args:
        arm: the arm (name, URDF path or ArmSpec), as for :func:`explore3d.world.explore.explore`.
        config: the :class:`~explore3d.strategy.explore.ExploreConfig` of the runs to be corrected (the
            gap depends on the controller and the mode); its ``face_offset`` is set to 0 and
            ``record`` to False for the calibration run.  None: ``ExploreConfig()``.
        calibration_object: the known object, a closed trimesh in its known world pose; None:
            :func:`calibration_sphere` (60 mm ball at the origin).  Never the object under test.
        reject_m: see :data:`REJECT_GAP_M`.
        label: description stored in the result (default: derived from the object).
        progress: passed to :func:`~explore3d.world.explore.explore`.

    Returns:
        :class:`ThicknessCalibration`; apply it with
        ``dataclasses.replace(config, face_offset=cal.face_offset_m)``.
    """

    t0 = time.perf_counter()
    config = ExploreConfig() if config is None else config
    if not isinstance(config, ExploreConfig):
        raise ValueError(f"config must be an ExploreConfig; got {type(config).__name__}")
    if calibration_object is None:
        calibration_object = calibration_sphere()
        label = label or f"sphere r={CALIBRATION_SPHERE_RADIUS_M * 1000:.0f} mm at the origin"
    if not hasattr(calibration_object, "vertices") or not getattr(calibration_object, "is_watertight", False):
        raise ValueError("calibration_object must be a closed (watertight) trimesh in its known world pose")
    if label is None:
        lo, hi = calibration_object.bounds
        label = f"mesh {np.round((hi - lo) * 1000, 1).tolist()} mm at {np.round((lo + hi) / 2 * 1000, 1).tolist()} mm"
    cfg = dataclasses.replace(config, face_offset=0.0, record=False, points="links")  # the thickness of link faces
    ex = explore(calibration_object, arm, cfg, progress=progress)
    gaps, _, _ = contact_point_gaps(ex, SignedDistance(calibration_object), unique=True)
    gaps = gaps[np.isfinite(gaps)]  # contact links that gave no points
    return thickness_from_gaps(gaps, reject_m, object=label, n_wraps=ex.n_wraps, steps=ex.steps,
                               wall_s=time.perf_counter() - t0)
