"""Side by side on the same sweeps: the paper's link points, our localised contacts and an ideal
skin (evaluation only).

:func:`compare` runs one exploration, reconstructs it three ways -- the paper's rule (the faces of
the contact-flagged links), the contacts localised from the joint torques (the pipeline's
default), and the ideal skin of :mod:`explore3d.world.skin` (every contact point PyBullet reports at the
same readings, hulled the same way) -- and scores the localisation against the skin.  The gap
between the columns is what the joint signals lose about *where* the arm touched; what the skin
misses too is what the sweeps never touched.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import asdict, dataclass

import numpy as np

from explore3d.app.pipeline import NoContactError, check_run_inputs, planar_truth, rough_bound_or
from explore3d.arm.urdf import load_arm
from explore3d.core.defaults import DEFAULT_A
from explore3d.geometry.metrics import shape_error
from explore3d.reconstruction.carve import carve
from explore3d.reconstruction.hull_input import reconstruct_points
from explore3d.strategy.explore import ExploreConfig, contact_points
from explore3d.world.explore import explore
from explore3d.world.skin import LOADED_FORCE_N, ideal_skin, surface_coverage

__all__ = ["CompareColumn", "compare", "compare_exploration", "format_compare"]


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


def _column(name, points, wrap, ctx, seed) -> CompareColumn:
    """Score ``points`` (m, >= d) hulled as the pipeline does (3D: carved by the exploration's swept
    free space ``ctx["swept"]`` when it has some); ``ctx``: d, centre, radius, a, method, truth, swept."""

    P = np.asarray(points, dtype=float)
    P = P.reshape(len(P), -1)[:, : ctx["d"]]
    try:
        hull = reconstruct_points(P, wrap, ctx["centre"], ctx["radius"], a=ctx["a"], method=ctx["method"])
        est = hull.shape()
        if ctx["d"] == 3 and ctx.get("swept"):
            est = carve(est, ctx["swept"]).mesh
        err = shape_error(est, ctx["truth"], seed=seed)
        e, iou, ch = err.percent, err.iou, err.chamfer_m
    except ValueError:  # too few points for a hull
        e, iou, ch = float("nan"), float("nan"), float("nan")
    c3, c6 = surface_coverage(ctx["truth"], P, seed=seed)
    return CompareColumn(name, e, iou, ch, c3, c6, int(len(P)))


def localisation_scores(exploration, skin, radius_m: float = 3.0e-3, used_only: bool = False) -> dict:
    """How well the localised contacts match the ideal skin at the same readings (evaluation only).

    For each settled reading (:attr:`explore3d.strategy.encircle.Attempt.moments`) the truth is every
    arm-object contact point PyBullet reports in the physics state that reading reports
    (:func:`explore3d.world.skin.ideal_skin`, kind ``"moment"``).  A localised contact is *correct* when
    a true point on the same link lies within ``radius_m`` of it in the wrap plane (the base x-y
    plane; the height across the link is unobservable and reported as an interval).

    Returns:
        a JSON-ready dict: ``n_localised``; ``inplane_median_m``, ``inplane_p90_m`` and
        ``3d_median_m``, ``3d_p90_m`` (distance to the nearest true point on the same link; to
        the nearest on any link when the link has none: ``n_without_same_link``);
        ``precision`` (correct / localised); ``recall_all`` (true contact links with a correct
        localised contact on them / true contact links, over all readings) and ``recall_loaded``
        (the same for links carrying at least :data:`explore3d.world.skin.LOADED_FORCE_N` in total) and
        ``recall_1n`` (links carrying at least 1 N: a force the default sensing resolves to 1 mm,
        :func:`explore3d.feeling.contacts.contact_uncertainty_m`), with their counts ``n_true_links``,
        ``n_true_loaded`` and ``n_true_1n``.
    """
    ex = exploration
    cs = ex.contacts.select(ex.contacts.used) if used_only else ex.contacts
    truth = {}  # (wrap, attempt, moment index) -> rows of the skin
    sel = np.flatnonzero(skin.kind == "moment")
    for i in sel:
        truth.setdefault((int(skin.wrap[i]), int(skin.attempt[i]), int(skin.moment[i])), []).append(i)
    d_in, d_3d, correct, no_same = [], [], [], 0
    found = set()  # (wrap, attempt, moment, link) localised correctly
    for j in range(len(cs)):
        w, a_, link = int(cs.wrap[j]), int(cs.attempt[j]), int(cs.link[j])
        att = ex.attempts[w][a_]
        mi = [m.joint for m in att.moments].index(int(cs.joint[j]))
        rows = np.array(truth.get((w, a_, mi), []), dtype=int)
        if len(rows) == 0:
            d_in.append(np.inf)
            d_3d.append(np.inf)
            correct.append(False)
            continue
        z = np.asarray(att.T_world_base, float)[:3, 2]
        same = rows[skin.link[rows] == link]
        cand = same if len(same) else rows
        no_same += int(len(same) == 0)
        D = skin.points[cand] - cs.points[j]
        inplane = np.linalg.norm(D - np.outer(D @ z, z), axis=1)
        d_in.append(float(inplane.min()))
        d_3d.append(float(np.linalg.norm(D, axis=1).min()))
        ok = len(same) > 0 and d_in[-1] <= radius_m
        correct.append(ok)
        if ok:
            found.add((w, a_, mi, link))
    true_links, loaded_links, links_1n = set(), set(), set()
    for key, rows in truth.items():
        force: dict = {}
        for i in rows:
            force[int(skin.link[i])] = force.get(int(skin.link[i]), 0.0) + float(skin.normal_force_n[i])
        for link, f in force.items():
            true_links.add(key + (link,))
            if f >= LOADED_FORCE_N:
                loaded_links.add(key + (link,))
            if f >= 1.0:
                links_1n.add(key + (link,))
    fin = np.array([d for d in d_in if np.isfinite(d)])
    fin3 = np.array([d for d in d_3d if np.isfinite(d)])

    def pct(v, q):
        return float(np.percentile(v, q)) if len(v) else float("nan")

    return {"n_localised": int(len(cs)), "used_only": used_only,
            "inplane_median_m": pct(fin, 50), "inplane_p90_m": pct(fin, 90),
            "3d_median_m": pct(fin3, 50), "3d_p90_m": pct(fin3, 90), "n_without_same_link": int(no_same),
            "precision": float(np.mean(correct)) if correct else float("nan"),
            "recall_all": len(found & true_links) / len(true_links) if true_links else float("nan"),
            "recall_loaded": len(found & loaded_links) / len(loaded_links) if loaded_links else float("nan"),
            "recall_1n": len(found & links_1n) / len(links_1n) if links_1n else float("nan"),
            "n_true_links": len(true_links), "n_true_loaded": len(loaded_links), "n_true_1n": len(links_1n),
            "radius_m": radius_m}


def compare(mesh, arm="default", config: ExploreConfig = ExploreConfig(), a: float = DEFAULT_A, *, centre=None,
            radius=None, seed: int = 0, progress=None) -> dict:
    """Explore ``mesh`` once and score four point sets of the same sweeps: the paper's link
    points (the faces of the contact-flagged links), our contacts localised from the joint
    torques (the pipeline's default), the ideal skin's contact points, and the ideal skin's
    points that carry force; and the localisation against the skin (:func:`localisation_scores`).

    Returns:
        a JSON-ready dict: ``columns`` (list of :class:`CompareColumn` dicts; NaN scores where a
        point set gives no hull), ``localisation``
        (all localised contacts) and ``localisation_used`` (those hulled), ``n_wraps``,
        ``n_contacts`` (detections), ``skin_contacts`` and ``skin_loaded`` (skin points),
        ``explore_s`` and ``skin_s`` (wall-clock seconds).
    """

    check_run_inputs(mesh, load_arm(arm), config, a, "exponential", centre, radius)
    config = dataclasses.replace(config, points="contacts")
    centre, radius = rough_bound_or(mesh, centre, radius)
    ex = explore(mesh, arm, config, centre=centre, radius=radius, progress=progress)
    return compare_exploration(ex, mesh, centre, radius, a=a, seed=seed)


def compare_exploration(ex, mesh, centre, radius: float, a: float = DEFAULT_A, *, seed: int = 0, skin=None) -> dict:
    """Score an exploration ``ex`` (made with ``config.points="contacts"``) of ``mesh`` as
    :func:`compare` does (same dict), without exploring again: e.g. to keep ``ex``'s contacts and
    free space.  ``centre`` (3,) and ``radius`` (m) are the rough bound it was explored with;
    ``skin``: ``ideal_skin(ex, mesh)`` when already computed (else computed here)."""


    config = ex.config
    if config.points != "contacts":
        raise ValueError(f"compare_exploration needs an exploration with config.points='contacts'; got "
                         f"{config.points!r}: explore with dataclasses.replace(config, points='contacts')")
    centre = np.asarray(centre, dtype=float)
    if ex.n_contacts == 0:
        raise NoContactError("the arm made no contact with the object: nothing to compare; use a longer arm, a "
                             "smaller object or a correct rough bound", exploration=ex)
    ctx = {"d": 2 if config.mode == "planar" else 3, "centre": centre, "radius": radius, "a": a,
           "method": "exponential", "swept": list(ex.swept),
           "truth": planar_truth(mesh, float(centre[2])) if config.mode == "planar" else mesh}
    t0 = time.perf_counter()
    skin = ideal_skin(ex, mesh) if skin is None else skin
    skin_s = time.perf_counter() - t0
    link_cfg = dataclasses.replace(config, points="links")
    L, Lw, _, _ = contact_points(ex.spec, ex.attempts, link_cfg)
    cols = [_column("link points (paper)", L, Lw, ctx, seed),
            _column("localised contacts", ex.points, ex.point_wrap, ctx, seed),
            _column("ideal skin, all contacts", skin.points, skin.wrap, ctx, seed),
            _column("ideal skin, loaded contacts", skin.points[skin.loaded], skin.wrap[skin.loaded], ctx, seed)]
    # the pipeline's own score is the second column's (same points, same hull); a column without
    # enough points for a hull scores NaN
    return {"mode": config.mode, "n_wraps": ex.n_wraps, "probe_wraps": int(sum(r["wraps"] for r in ex.probe_rounds)),
            "carved": bool(ctx["swept"]) and config.mode == "3d", "n_contacts": ex.n_contacts, "skin_contacts": len(skin),
            "skin_loaded": int(skin.loaded.sum()), "explore_s": float(ex.wall_s), "skin_s": float(skin_s),
            "columns": [c.to_dict() for c in cols],
            "localisation": localisation_scores(ex, skin),
            "localisation_used": localisation_scores(ex, skin, used_only=True)}


def format_compare(report: dict) -> str:
    """The columns of :func:`compare` as a Markdown table, then the localisation figures."""
    cols = report["columns"]
    rows = [("volume error" if report["mode"] == "3d" else "area error", "percent_error", "{:.2f}%"),
            ("IoU", "iou", "{:.3f}"), ("Chamfer", "chamfer_m", lambda v: f"{1000 * v:.2f} mm"),
            ("coverage 3 mm", "coverage_3mm", lambda v: f"{100 * v:.1f}%"),
            ("coverage 6 mm", "coverage_6mm", lambda v: f"{100 * v:.1f}%"), ("points", "n_points", "{:d}")]
    out = ["| | " + " | ".join(c["name"] for c in cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for label, key, fmt in rows:
        f = fmt.format if isinstance(fmt, str) else fmt
        out.append(f"| {label} | " + " | ".join(f(c[key]) for c in cols) + " |")
    if "localisation" in report:
        out += ["", "| localisation vs ideal skin | all localised | hulled |", "|---|---|---|"]
        A, U = report["localisation"], report["localisation_used"]
        mm = lambda v: f"{1000 * v:.2f} mm"  # noqa: E731
        pc = lambda v: f"{100 * v:.1f}%"  # noqa: E731
        for label, key, f in (("contacts", "n_localised", str), ("in-plane median", "inplane_median_m", mm),
                              ("in-plane p90", "inplane_p90_m", mm), ("3D median", "3d_median_m", mm),
                              ("3D p90", "3d_p90_m", mm), ("precision (3 mm, in plane)", "precision", pc),
                              ("recall, all true contact links", "recall_all", pc),
                              ("recall, links carrying >= 1 mN", "recall_loaded", pc),
                              ("recall, links carrying >= 1 N", "recall_1n", pc)):
            out.append(f"| {label} | {f(A[key])} | {f(U[key])} |")
    return "\n".join(out)
