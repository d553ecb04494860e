"""Why does the Table I replica differ from the paper?  (measurement study, no package changes)

Planar mode, the paper arm (4 x 110 mm links, 40 mm wide), 4 attempts per wrap, a = 0.2.
Writes table1_study/results.json and PNGs in table1_study/ (in the current folder):

    python scripts/studies/table1_study.py [--quick]

Sections (keys of results.json):
  baseline    Table I rows as the package gives them, with the error split into over-estimate
              (estimate - truth) and under-estimate (truth - estimate), per side wedge of the object
              (the start side is -y: the straight arm lies along +x below the object and curls to +y).
  link_gaps   for every contact-flagged link: the distance of its inner face to the truth (0 = touching).
  perfect     inverse hull (a = 0.2, the rough centre) of "perfect contacts": (i) the contact links'
              inner faces translated along their normals onto the truth; (ii) dense samples of the
              truth boundary; (iii) dense samples restricted to the boundary the arm's faces came
              within 2 mm of (the rest left unexplored).
  a_sweep     the baseline points reconstructed with other a.
  placement   the cube/cylinder explored with the straight arm's inner face `gap` mm from the object's
              near side (the package: rough radius 1.05 x the 3D half-diagonal + 10 mm clearance) and
              with the object's centre `lead` mm along the arm from the base (package: lead = radius).
              Done by replacing explore3d.strategy.explore.wrap_poses inside this script only; the
              reconstruction's rough centre/radius stay the package's.
  mirror      the paper's Fig. 7 "mirrored results" vs ours (second wrap = the arm turned over,
              x -> -x through the centre, same start side) vs a mirror across the arm's axis (y -> -y).
  cylinder_d  the cylinder of 63 mm DIAMETER (the paper's area 0.0031 m^2) instead of radius.
"""
from __future__ import annotations

import contextlib
import json
import math
import time
from pathlib import Path

import numpy as np
from shapely.geometry import LineString, Point, Polygon, box as sbox
from shapely.ops import unary_union

import importlib

ex_mod = importlib.import_module("explore3d.strategy.explore")  # the module (the package re-exports the function)
from explore3d.geometry.directions import planar_wrap_poses
from explore3d.strategy.explore import ExploreConfig
from explore3d.geometry.hull import inverse_hull
from explore3d.geometry.metrics import shape_error
from explore3d.world.objects import cylinder, load_object
from explore3d.app.pipeline import reconstruct_exploration, run

OUT = Path(__file__).resolve().parents[2] / "table1_study"
A = 0.2
ARM = "paper"
HALF = {"cube": 0.04, "cylinder": 0.063, "cylinder_d63": 0.0315}  # near-side distance from the centre, m


def mesh_of(name):
    if name == "cylinder_d63":
        return cylinder(radius=0.0315, height=0.08)
    return load_object(name)


# ---------------------------------------------------------------------------------------------
# placement override (this script only)
# ---------------------------------------------------------------------------------------------
@contextlib.contextmanager
def placement(gap=None, lead=None, half=None):
    """Place the planar wraps so the straight arm's inner face is ``gap`` m outside the object's
    near side (``half`` m from the centre) and the centre is ``lead`` m along the arm; None keeps
    the package's choice for that quantity."""
    orig = ex_mod.wrap_poses

    def patched(spec, config, centre, radius):
        r_place = radius if gap is None else half + gap
        clearance = config.clearance if gap is None else 0.0
        ld = radius if lead is None else lead  # the package's lead (= its rough radius) unless given
        if gap is None and lead is None:
            return orig(spec, config, centre, radius)
        return planar_wrap_poses(centre, r_place, spec.link_width, config.directions, config.mirrored,
                                 clearance=clearance, lead=ld)

    ex_mod.wrap_poses = patched
    try:
        yield
    finally:
        ex_mod.wrap_poses = orig


def run_case(obj, directions, mirrored, gap=None, lead=None, attempts=4):
    cfg = ExploreConfig(mode="planar", directions=directions, mirrored=mirrored, attempts=attempts)
    with placement(gap, lead, HALF[obj]):
        return run(mesh_of(obj), ARM, cfg, a=A)


# ---------------------------------------------------------------------------------------------
# geometry helpers
# ---------------------------------------------------------------------------------------------
SIDES = {"-y (start side)": -90.0, "+x": 0.0, "+y": 90.0, "-x": 180.0}


def wedge(angle_deg, R=1.0):
    a0, a1 = math.radians(angle_deg - 45), math.radians(angle_deg + 45)
    return Polygon([(0, 0), (R * math.cos(a0), R * math.sin(a0)), (R * math.cos(a1), R * math.sin(a1))])


def split_error(est, truth, corner=0.015):
    """Over/under areas (m^2 and % of the true area), per side wedge, and the part within
    ``corner`` m (Chebyshev) of the square's corners."""
    A0 = truth.area
    over, under = est.difference(truth), truth.difference(est)
    out = {"true_area_m2": A0, "estimate_area_m2": est.area,
           "over_pct": 100 * over.area / A0, "under_pct": 100 * under.area / A0,
           "total_pct": 100 * (over.area + under.area) / A0, "sides": {}}
    for name, ang in SIDES.items():
        w = wedge(ang)
        out["sides"][name] = {"over_pct": 100 * over.intersection(w).area / A0,
                              "under_pct": 100 * under.intersection(w).area / A0}
    minx, miny, maxx, maxy = truth.bounds
    corners = unary_union([sbox(x - corner, y - corner, x + corner, y + corner)
                           for x in (minx, maxx) for y in (miny, maxy)])
    out["corner_boxes_mm"] = 2 * corner * 1000
    out["in_corner_boxes_pct"] = {"over": 100 * over.intersection(corners).area / A0,
                                  "under": 100 * under.intersection(corners).area / A0}
    return out, over, under


def faces_of(res):
    """Per contact-flagged link: (wrap, attempt, link, inner-face segment (2, 2), inward unit normal)."""
    from explore3d.arm.kinematics import link_transforms

    ex = res.exploration
    spec = ex.spec
    out = []
    for w, atts in enumerate(ex.attempts):
        for k, att in enumerate(atts):
            T = link_transforms(spec, att.q, att.T_world_base)
            for i in np.nonzero(att.contact)[0]:
                p0 = (T[i] @ [0, spec.link_width / 2, 0, 1])[:2]
                p1 = (T[i] @ [spec.link_length, spec.link_width / 2, 0, 1])[:2]
                n = T[i][:2, 1]  # link +y in world = towards the curl
                out.append((w, k, int(i), np.array([p0, p1]), n))
    return out


def link_gaps(res):
    rows = []
    for w, k, i, seg, n in faces_of(res):
        line = LineString(seg)
        d = line.distance(res.truth)
        inter = line.intersects(res.truth)
        rows.append({"wrap": w, "attempt": k, "link": i + 1, "gap_mm": 1000 * d, "penetrates": bool(inter)})
    return rows


def hull_err(points, truth, centre=(0.0, 0.0), a=A):
    h = inverse_hull(np.asarray(points), centre=np.asarray(centre, float), a=a)
    e = shape_error(h.shape(), truth)
    return e.percent, h


def perfect_contacts(res, n_along=5):
    """The contact links' inner faces moved along their normals until they touch the truth:
    (points (m, 2), wrap ids (m,))."""
    pts, wr = [], []
    for w, k, i, seg, n in faces_of(res):
        d = LineString(seg).distance(res.truth)
        if LineString(seg).intersects(res.truth):
            d = 0.0
        s = np.linspace(0, 1, n_along)[:, None]
        P = seg[0] + s * (seg[1] - seg[0]) + d * n
        pts.append(P)
        wr.append(np.full(len(P), w))
    return np.vstack(pts), np.concatenate(wr)


def halfplane_bound(res):
    """Intersection of the inner half-planes of every contact link's inner-face line (the free space
    the contacts prove, for a convex object; the best any point rule could do with these links)."""
    B = sbox(-0.3, -0.3, 0.3, 0.3)
    for w, k, i, seg, n in faces_of(res):
        p0 = seg[0]
        t = (seg[1] - seg[0]) / np.linalg.norm(seg[1] - seg[0])
        big = 1.0
        hp = Polygon([p0 - big * t, p0 + big * t, p0 + big * t + big * n, p0 - big * t + big * n])
        B = B.intersection(hp)
    return B


def boundary_samples(poly, n=4000):
    ring = poly.exterior
    return np.array([ring.interpolate(t, normalized=True).coords[0] for t in np.linspace(0, 1, n, endpoint=False)])


def touched_boundary(res, tol=0.002, n=4000):
    """Dense truth-boundary samples within ``tol`` m of some contact link's inner face."""
    B = boundary_samples(res.truth, n)
    segs = unary_union([LineString(seg) for *_, seg, _n in faces_of(res)])
    keep = np.array([segs.distance(Point(p)) <= tol for p in B])
    return B[keep], keep.mean()


# ---------------------------------------------------------------------------------------------
# pictures
# ---------------------------------------------------------------------------------------------
def figure(res, path, title, over=None, under=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon as MPoly

    from explore3d.arm.kinematics import link_transforms

    ex = res.exploration
    spec = ex.spec
    fig, ax = plt.subplots(figsize=(7, 7))
    cmap = plt.get_cmap("tab10")
    L, W = spec.link_length, spec.link_width
    rect = np.array([[0, -W / 2, 0, 1], [L, -W / 2, 0, 1], [L, W / 2, 0, 1], [0, W / 2, 0, 1]]).T
    for w, atts in enumerate(ex.attempts):
        for k, att in enumerate(atts):
            T = link_transforms(spec, att.q, att.T_world_base)
            c = cmap(4 * w + k)
            for i in range(spec.n_links):
                R = (T[i] @ rect)[:2].T
                ax.add_patch(MPoly(R, closed=True, fill=False, ec=c, lw=1.6 if att.contact[i] else 0.6,
                                   ls="-" if att.contact[i] else ":"))
            ax.plot([], [], color=c, label=f"wrap {w + 1} ({ex.poses[w].label}) attempt {k + 1}")
    # straight (start) arm of every wrap
    for w, p in enumerate(ex.poses):
        T = np.asarray(p.T_world_base)
        for i in range(spec.n_links):
            R = (T @ (rect + np.array([[i * L], [0], [0], [0]])))[:2].T
            ax.add_patch(MPoly(R, closed=True, fill=True, fc="0.85", ec="0.5", lw=0.5, alpha=0.5))
    ax.plot([], [], color="0.6", lw=4, alpha=0.5, label="straight start arm")
    P = ex.points
    ax.plot(P[:, 0], P[:, 1], "k.", ms=3, label="link points (inner faces)")
    t = np.asarray(res.truth.exterior.coords)
    ax.fill(t[:, 0], t[:, 1], color="0.55", alpha=0.35, label="truth")
    e = np.asarray(res.estimate.exterior.coords)
    ax.plot(e[:, 0], e[:, 1], "-", color="crimson", lw=2.2, label="estimate (a=0.2)")
    for geom, col, lab in ((over, "orange", "over-estimate"), (under, "royalblue", "under-estimate")):
        if geom is None or geom.is_empty:
            continue
        for j, g in enumerate(getattr(geom, "geoms", [geom])):
            if g.geom_type != "Polygon":
                continue
            xy = np.asarray(g.exterior.coords)
            ax.fill(xy[:, 0], xy[:, 1], color=col, alpha=0.55, label=lab if j == 0 else None)
    ax.plot(*res.centre[:2], "k+", ms=12)
    ax.set_aspect("equal")
    ax.set_xlim(-0.2, 0.2)
    ax.set_ylim(-0.16, 0.2)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=6.5, loc="upper left")
    ax.set_title(f"{title}: error {res.error.percent:.1f} %")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def sweep_figure(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for obj, dirs, mk in (("cube", 1, "o-"), ("cube", 2, "s-"), ("cylinder", 1, "o--"), ("cylinder", 2, "s--")):
        rr = [r for r in rows if r["object"] == obj and r["directions"] == dirs and r.get("lead_mm") is None
              and r.get("ok")]
        rr.sort(key=lambda r: r["gap_mm"])
        ax.plot([r["gap_mm"] for r in rr], [r["percent"] for r in rr], mk, label=f"{obj}, {dirs} dir")
    for y, lab in ((40.6, "paper cube 1"), (21.9, "paper cube 2"), (41.9, "paper cyl 1"), (28.4, "paper cyl 2")):
        ax.axhline(y, color="0.6", lw=0.6, ls=":")
        ax.text(1, y + 0.6, lab, fontsize=7, color="0.4")
    ax.set_xlabel("start gap: straight arm's inner face to the object's near side [mm]")
    ax.set_ylabel("area error [%]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
def main(quick=False):
    OUT.mkdir(exist_ok=True)
    results = {"machine": {}, "baseline": [], "link_gaps": {}, "perfect": [], "a_sweep": [], "placement": [],
               "mirror": [], "cylinder_d": []}
    import os
    import platform

    results["machine"] = {"platform": platform.platform(), "python": platform.python_version(),
                          "cpus": os.cpu_count()}
    t_start = time.time()
    base = {}
    # --- baseline ----------------------------------------------------------------------------
    for obj in ("cube", "cylinder"):
        for dirs, mir in ((1, False), (2, True)):
            res = run_case(obj, dirs, mir)
            base[(obj, dirs)] = res
            sp, over, under = split_error(res.estimate, res.truth)
            T0 = np.asarray(res.exploration.poses[0].T_world_base)
            results["baseline"].append({"object": obj, "directions": dirs, "percent": res.error.percent,
                                        "rough_radius_mm": 1000 * res.radius,
                                        "base_xy_mm": (1000 * T0[:2, 3]).tolist(),
                                        "start_gap_mm": 1000 * (res.radius + 0.01 - HALF[obj]),
                                        "n_points": int(len(res.exploration.points)),
                                        "n_attempts": [len(w) for w in res.exploration.attempts],
                                        "contacts": [[a.contact.astype(int).tolist() for a in w]
                                                     for w in res.exploration.attempts],
                                        "q": [[np.round(a.q, 3).tolist() for a in w] for w in res.exploration.attempts],
                                        **sp})
            results["link_gaps"][f"{obj} {dirs}"] = link_gaps(res)
            figure(res, OUT / f"{obj}_{dirs}dir.png", f"{obj}, {dirs} direction(s), package placement", over, under)
            print("baseline", obj, dirs, f"{res.error.percent:.1f}", f"over {sp['over_pct']:.1f} under {sp['under_pct']:.1f}",
                  flush=True)
    # --- perfect contacts / reconstruction alone --------------------------------------------
    for (obj, dirs), res in base.items():
        row = {"object": obj, "directions": dirs, "package": res.error.percent}
        from explore3d.reconstruction.hull_input import reconstruct_points

        Pm, Wm = perfect_contacts(res)
        h = reconstruct_points(Pm, Wm, res.centre, res.radius, a=A)
        row["faces_moved_onto_truth"] = shape_error(h.shape(), res.truth).percent
        hp = halfplane_bound(res)
        sp, _, _ = split_error(hp, res.truth)
        row["halfplane_bound"] = sp["total_pct"]
        row["halfplane_bound_over_under"] = [sp["over_pct"], sp["under_pct"]]
        row["convex_hull_of_package_estimate"] = split_error(res.estimate.convex_hull, res.truth)[0]["total_pct"]
        row["dense_full_boundary"], _ = hull_err(boundary_samples(res.truth), res.truth)
        Bt, frac = touched_boundary(res)
        row["touched_boundary_fraction"] = frac
        try:
            row["dense_touched_boundary"], _ = hull_err(Bt, res.truth)
        except ValueError as exc:
            row["dense_touched_boundary"] = str(exc)[:80]
        results["perfect"].append(row)
        print("perfect", row, flush=True)
    # --- a sweep on the baseline points -----------------------------------------------------
    for (obj, dirs), res in base.items():
        for a in (0.02, 0.05, 0.1, 0.2, 0.5, 1.0):
            h = reconstruct_exploration(res.exploration, res.centre, res.radius, a=a)
            results["a_sweep"].append({"object": obj, "directions": dirs, "a": a,
                                       "percent": shape_error(h.shape(), res.truth).percent})
    # --- mirror variants (points only, no new simulation) -----------------------------------
    for obj in ("cube", "cylinder"):
        r1 = base[(obj, 1)]
        P = r1.exploration.points
        truth = r1.truth
        for name, M in (("ours: x -> -x (second arm from the other end, same start side)", np.diag([-1.0, 1.0])),
                        ("y -> -y (start sides opposite)", np.diag([1.0, -1.0])),
                        ("point reflection (rotated 180 deg)", np.diag([-1.0, -1.0]))):
            Q = np.vstack([P, P @ M])
            pct, h = hull_err(Q, truth)
            sp, _, _ = split_error(h.shape(), truth)
            results["mirror"].append({"object": obj, "mirror": name, "percent": pct,
                                      "over_pct": sp["over_pct"], "under_pct": sp["under_pct"]})
        results["mirror"].append({"object": obj, "mirror": "simulated mirrored wrap (package)",
                                  "percent": base[(obj, 2)].error.percent})
    # --- placement ---------------------------------------------------------------------------
    gaps = (2, 5, 10, 20, 30) if quick else (1, 2, 5, 10, 15, 20, 25, 30, 40, 50)
    for obj in ("cube", "cylinder"):
        pkg_gap = 1000 * (base[(obj, 1)].radius + 0.01 - HALF[obj])
        for dirs, mir in ((1, False), (2, True)):
            for g in sorted(set(gaps) | {round(pkg_gap, 1)}):
                row = {"object": obj, "directions": dirs, "gap_mm": g, "lead_mm": None}
                try:
                    res = run_case(obj, dirs, mir, gap=g / 1000)
                    sp, over, under = split_error(res.estimate, res.truth)
                    row.update(ok=True, percent=res.error.percent, over_pct=sp["over_pct"],
                               under_pct=sp["under_pct"], start_side_over_pct=sp["sides"]["-y (start side)"]["over_pct"],
                               n_attempts=[len(w) for w in res.exploration.attempts])
                    if obj == "cube" and g in (2, 5) and not quick:
                        figure(res, OUT / f"{obj}_{dirs}dir_gap{g}mm.png",
                               f"{obj}, {dirs} dir, start gap {g} mm", over, under)
                except Exception as exc:  # noqa: BLE001 - recorded
                    row.update(ok=False, error=f"{type(exc).__name__}: {str(exc)[:100]}")
                results["placement"].append(row)
                print("placement", row, flush=True)
        # lead at the package's gap and at 5 mm
        for g in (None, 5):
            for lead in (0.04, 0.06, 0.08, 0.10, 0.12, 0.14):
                row = {"object": obj, "directions": 2, "gap_mm": pkg_gap if g is None else g, "lead_mm": 1000 * lead}
                try:
                    res = run_case(obj, 2, True, gap=None if g is None else g / 1000, lead=lead)
                    row.update(ok=True, percent=res.error.percent)
                except Exception as exc:  # noqa: BLE001
                    row.update(ok=False, error=f"{type(exc).__name__}: {str(exc)[:100]}")
                results["placement"].append(row)
                print("lead", row, flush=True)
    sweep_figure(results["placement"], OUT / "gap_sweep.png")
    # --- gap x lead grid: the spread of the error over plausible placements --------------------
    results["grid"] = []
    g_vals = (2, 5, 10, 20, 30, 42.7) if quick else (2, 5, 10, 15, 20, 25, 30, 35, 42.7)
    l_vals = np.arange(0.03, 0.1501, 0.02 if quick else 0.01)
    for obj in ("cube", "cylinder", "cylinder_d63"):
        for dirs, mir in ((1, False), (2, True)):
            for g in g_vals:
                for lead in l_vals:
                    row = {"object": obj, "directions": dirs, "gap_mm": g, "lead_mm": round(1000 * lead, 1)}
                    try:
                        res = run_case(obj, dirs, mir, gap=g / 1000, lead=float(lead))
                        row.update(ok=True, percent=res.error.percent)
                    except Exception as exc:  # noqa: BLE001
                        row.update(ok=False, error=f"{type(exc).__name__}")
                    results["grid"].append(row)
            pc = [r["percent"] for r in results["grid"] if r["object"] == obj and r["directions"] == dirs and r["ok"]]
            print("grid", obj, dirs, len(pc), np.percentile(pc, [0, 10, 25, 50, 75, 90, 100]).round(1), flush=True)
    # --- the 63 mm diameter cylinder ----------------------------------------------------------
    for dirs, mir in ((1, False), (2, True)):
        for g in (None, 5):
            row = {"object": "cylinder d 63 mm", "directions": dirs, "gap_mm": g}
            try:
                res = run_case("cylinder_d63", dirs, mir, gap=None if g is None else g / 1000)
                row.update(ok=True, percent=res.error.percent, area_error_m2=res.error.sym_diff,
                           true_area_m2=res.truth.area, rough_radius_mm=1000 * res.radius)
                if g is None:
                    sp, over, under = split_error(res.estimate, res.truth)
                    figure(res, OUT / f"cylinder_d63_{dirs}dir.png", f"cylinder 63 mm diameter, {dirs} dir", over, under)
            except Exception as exc:  # noqa: BLE001
                row.update(ok=False, error=f"{type(exc).__name__}: {str(exc)[:100]}")
            results["cylinder_d"].append(row)
            print("cyl d63", row, flush=True)
    results["wall_s"] = time.time() - t_start
    (OUT / "results.json").write_text(json.dumps(results, indent=1, default=float) + "\n")
    print("wrote", OUT / "results.json", f"{results['wall_s']:.0f} s")
    grid_figure()


def grid_figure(path=None):
    """Heat maps of the gap x lead grid in results.json (``--figures``: no simulation)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = json.loads((OUT / "results.json").read_text())
    cases = [("cube", 1, 40.6), ("cube", 2, 21.9), ("cylinder", 1, 41.9), ("cylinder", 2, 28.4),
             ("cylinder_d63", 1, 41.9), ("cylinder_d63", 2, 28.4)]
    fig, axes = plt.subplots(3, 2, figsize=(10, 11))
    for ax, (obj, d, paper) in zip(axes.ravel(), cases):
        rows = [x for x in r["grid"] if x["object"] == obj and x["directions"] == d]
        gs = sorted({x["gap_mm"] for x in rows})
        ls = sorted({x["lead_mm"] for x in rows})
        Z = np.full((len(gs), len(ls)), np.nan)
        for x in rows:
            if x["ok"]:
                Z[gs.index(x["gap_mm"]), ls.index(x["lead_mm"])] = x["percent"]
        im = ax.imshow(Z, origin="lower", aspect="auto", cmap="viridis", vmin=0, vmax=75,
                       extent=(ls[0] - 5, ls[-1] + 5, -0.5, len(gs) - 0.5))
        ax.set_yticks(range(len(gs)), [str(g) for g in gs])
        ax.set_xlabel("lead: object centre along the straight arm from the base [mm]")
        ax.set_ylabel("start gap [mm]")
        pc = np.nanpercentile(Z, [10, 50, 90])
        ax.set_title(f"{obj}, {d} dir: median {pc[1]:.0f}% (10-90%: {pc[0]:.0f}-{pc[2]:.0f}), paper {paper}%",
                     fontsize=9)
        fig.colorbar(im, ax=ax, label="area error %")
    fig.tight_layout()
    fig.savefig(path or OUT / "placement_grid.png", dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a coarse placement grid (minutes less)")
    ap.add_argument("--figures", action="store_true", help="only redraw the grid from table1_study/results.json")
    args = ap.parse_args()
    if args.figures:
        grid_figure()
    else:
        main(quick=args.quick)
