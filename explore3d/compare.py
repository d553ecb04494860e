"""Side by side on the same sweeps: the paper's link points against an ideal skin (evaluation only).

:func:`compare` runs one exploration, reconstructs it as the pipeline does (the paper's rule: the
faces of the contact-flagged links), and re-runs its sweeps with the ideal skin of
:mod:`explore3d.skin` (every contact point PyBullet reports at the same readings, hulled the same
way).  The gap between the columns is what the joint signals lose about *where* the arm touched;
what the skin misses too is what the sweeps never touched.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .defaults import DEFAULT_A
from .explore import ExploreConfig

__all__ = ["CompareColumn", "compare", "format_compare"]


@dataclass(frozen=True)
class CompareColumn:
    """One way of turning the same sweeps into a shape.

    Attributes:
        name: what the points are.
        percent_error: symmetric difference / true size x 100.
        iou: intersection over union.
        chamfer_m: symmetric Chamfer distance of the surfaces, metres.
        coverage_3mm, coverage_6mm: fraction of the true surface within 3 / 6 mm of a point.
        n_points: points given to the hull (before its bound and outlier filter).
    """

    name: str
    percent_error: float
    iou: float
    chamfer_m: float
    coverage_3mm: float
    coverage_6mm: float
    n_points: int

    def to_dict(self) -> dict:
        return asdict(self)


def _column(name, points, wrap, res, seed) -> CompareColumn:
    from .metrics import shape_error
    from .pipeline import reconstruct_points
    from .skin import surface_coverage

    d = res.exploration.points.shape[1]
    P = np.asarray(points, dtype=float)[:, :d]
    try:
        hull = reconstruct_points(P, wrap, res.centre, res.radius, a=res.hull.a, method=res.hull.method)
        err = shape_error(hull.shape(), res.truth, seed=seed)
        e, iou, ch = err.percent, err.iou, err.chamfer_m
    except ValueError:  # too few points for a hull
        e, iou, ch = float("nan"), float("nan"), float("nan")
    c3, c6 = surface_coverage(res.truth, P, seed=seed)
    return CompareColumn(name, e, iou, ch, c3, c6, int(len(P)))


def compare(mesh, arm="default", config: ExploreConfig = ExploreConfig(), a: float = DEFAULT_A, *, centre=None,
            radius=None, seed: int = 0, progress=None) -> dict:
    """Explore ``mesh`` once and score three point sets of the same sweeps: the link points of
    the contact-flagged links (the pipeline's estimate), the ideal skin's contact points, and the
    ideal skin's points that carry force.

    Returns:
        a JSON-ready dict: ``columns`` (list of :class:`CompareColumn` dicts), ``n_wraps``,
        ``n_contacts`` (detections), ``skin_contacts`` and ``skin_loaded`` (skin points),
        ``explore_s`` and ``skin_s`` (wall-clock seconds).
    """
    import time

    from .pipeline import run
    from .skin import ideal_skin

    res = run(mesh, arm, config, a=a, centre=centre, radius=radius, seed=seed, progress=progress)
    ex = res.exploration
    t0 = time.perf_counter()
    skin = ideal_skin(ex, mesh)
    skin_s = time.perf_counter() - t0
    cols = [_column("link points (paper)", ex.points, ex.point_wrap, res, seed),
            _column("ideal skin, all contacts", skin.points, skin.wrap, res, seed),
            _column("ideal skin, loaded contacts", skin.points[skin.loaded], skin.wrap[skin.loaded], res, seed)]
    # the pipeline's own score is the first column's (same points, same hull)
    return {"mode": config.mode, "n_wraps": ex.n_wraps, "n_contacts": ex.n_contacts, "skin_contacts": len(skin),
            "skin_loaded": int(skin.loaded.sum()), "explore_s": float(ex.wall_s), "skin_s": float(skin_s),
            "columns": [c.to_dict() for c in cols]}


def format_compare(report: dict) -> str:
    """The columns of :func:`compare` as a Markdown table."""
    cols = report["columns"]
    rows = [("volume error" if report["mode"] == "3d" else "area error", "percent_error", "{:.2f}%"),
            ("IoU", "iou", "{:.3f}"), ("Chamfer", "chamfer_m", lambda v: f"{1000 * v:.2f} mm"),
            ("coverage 3 mm", "coverage_3mm", lambda v: f"{100 * v:.1f}%"),
            ("coverage 6 mm", "coverage_6mm", lambda v: f"{100 * v:.1f}%"), ("points", "n_points", "{:d}")]
    out = ["| | " + " | ".join(c["name"] for c in cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for label, key, fmt in rows:
        f = fmt.format if isinstance(fmt, str) else fmt
        out.append(f"| {label} | " + " | ".join(f(c[key]) for c in cols) + " |")
    return "\n".join(out)
