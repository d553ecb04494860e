"""The report of a sweep (:mod:`explore3d.app.sweep`): tables, a plot and an HTML page.

:func:`write_sweep_report` reads ``sweep.db`` and writes into its report folder:

* ``report.md`` and ``report.csv``: one row per (object, settings, seed): the swept settings, the
  status, the error (volume error in 3D, area error planar, %), IoU, Chamfer distance (mm), the
  run's time (s) and the failure reason (and, when the sweep grades by grasping, the fraction of
  grasps that held per source, :data:`GRASP_COLUMNS`); ``report.md`` also has a summary per object;
* ``errors.png``: the error against each swept setting (matplotlib, Agg), one line per object
  and combination of the other settings;
* ``report.html``: the table with a thumbnail per run (``thumbs/<key>.png``): the estimate
  (``runs/<key>/estimate.stl``) coloured by its signed distance to the truth (``truths/*.stl``), mm
  (:func:`explore3d.app.pictures.signed_distance_figure`); planar runs: the estimate polygon
  (``estimate_polygon.json``) against the true section at the arm's plane.

Thumbnails of stored runs never change (a run's files are written once), so they are made once.
"""
from __future__ import annotations

import csv
import html
import io
import json
import math
import os
import tempfile
from pathlib import Path

import trimesh
from shapely.geometry import Polygon

from explore3d.app.grasp import SOURCES
from explore3d.app.pictures import _plt, _save, signed_distance_figure
from explore3d.app.pipeline import planar_truth
from explore3d.app.sweep import read_rows
from explore3d.core.io import atomic_write_text

__all__ = ["report_table", "swept_keys", "write_sweep_report"]

#: Columns of report.csv after the swept settings.
RESULT_COLUMNS = ("status", "error_percent", "iou", "chamfer_mm", "time_s", "reason", "key")


def _settings(row) -> dict:
    return json.loads(row["settings"])


def swept_keys(rows) -> list[str]:
    """Settings with more than one value among ``rows`` (plus ``seed`` when it varies), sorted."""
    values: dict = {}
    for r in rows:
        s = {**_settings(r), "seed": r["seed"]}
        for k, v in s.items():
            values.setdefault(k, set()).add(json.dumps(v))
    keys = {k for r in rows for k in _settings(r)} | {"seed"}
    # a key missing from some rows takes the run's default there: it varies too
    return sorted(k for k in keys if len(values.get(k, ())) > 1 or any(k not in _settings(r) and k != "seed"
                                                                        for r in rows))


def _value(row, key):
    if key == "seed":
        return row["seed"]
    return _settings(row).get(key, "(default)")


#: Columns added after ``chamfer_mm`` when a run of the sweep was graded by grasping (the ``grasp``
#: setting): the fraction of the grasps planned on each source that held on the truth
#: (:mod:`explore3d.app.grasp`).
GRASP_COLUMNS = tuple(f"grasp_{name}" for name in SOURCES)


def _grasp_rates(row) -> list:
    entry = json.loads(row["report"]).get("grasp") if row["status"] == "ok" and row["report"] else None
    return [None if entry is None or name not in entry else entry[name]["rate"] for name in SOURCES]


def report_table(rows) -> tuple[list[str], list[list]]:
    """Header and rows (values, not text) of the per-run table: object, swept settings,
    :data:`RESULT_COLUMNS` (with :data:`GRASP_COLUMNS` after ``chamfer_mm`` when any run was
    graded by grasping)."""
    keys = swept_keys(rows)
    grasps = [_grasp_rates(r) for r in rows]
    graded = any(v is not None for g in grasps for v in g)
    extra = list(GRASP_COLUMNS) if graded else []
    header = ["object", *keys, *RESULT_COLUMNS[:4], *extra, *RESULT_COLUMNS[4:]]
    out = []
    for r, g in zip(rows, grasps):
        ok = r["status"] == "ok"
        out.append([r["object"], *(_value(r, k) for k in keys), r["status"],
                    r["percent_error"] if ok else None, r["iou"] if ok else None,
                    1e3 * r["chamfer_m"] if ok else None, *(g if graded else []), r["time_s"], r["reason"] or "",
                    r["key"]])
    return header, out


def _fmt(v, digits=3) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.{digits}g}" if abs(v) >= 1e4 else f"{v:.{digits}f}"
    return str(v)


def _cells(header, row) -> list[str]:
    """Text of a table row: results rounded, settings as given."""
    fmt = {"error_percent": 2, "iou": 3, "chamfer_mm": 2, "time_s": 1, **{c: 2 for c in GRASP_COLUMNS}}
    return [_fmt(v, fmt[h]) if h in fmt else ("" if v is None else str(v)) for h, v in zip(header, row)]


def _short(name: str) -> str:
    return Path(name).name if ("/" in name or "\\" in name) and not name.startswith("pybullet_data:") else name


def _markdown(rows, header, table) -> str:
    lines = ["# Sweep report", "", f"{len(rows)} runs, {sum(r['status'] == 'ok' for r in rows)} ok, "
             f"{sum(r['status'] != 'ok' for r in rows)} failed.  Error: volume (3D) or area (planar) symmetric "
             "difference / true size, %; Chamfer: symmetric, mm; time: wall-clock s of the run.", "",
             "## Per object", "", "| object | runs | ok | failed | median error % | best error % |",
             "|---|---|---|---|---|---|"]
    by_obj: dict = {}
    for r in rows:
        by_obj.setdefault(r["object"], []).append(r)
    for obj, rs in by_obj.items():
        errs = sorted(r["percent_error"] for r in rs if r["status"] == "ok")
        med = errs[len(errs) // 2] if len(errs) % 2 else (0.5 * (errs[len(errs) // 2 - 1] + errs[len(errs) // 2])
                                                          if errs else None)
        lines.append(f"| {_short(obj)} | {len(rs)} | {len(errs)} | {len(rs) - len(errs)} | {_fmt(med, 2)} | "
                     f"{_fmt(errs[0] if errs else None, 2)} |")
    lines += ["", "## Per object and setting", "", "| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    for row in table:
        cells = _cells(header, row)
        cells[0] = _short(cells[0])
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def _csv(header, table) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in table:
        w.writerow(["" if v is None else (repr(v) if isinstance(v, float) else v) for v in row])
    return buf.getvalue()


def _numeric(values) -> bool:
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)


#: Units of the settings on the plot's axes (the rest are counts, names or the dimensionless ``a``).
_UNITS = {"size": " [m]", "clearance": " [m]", "collision_margin": " [m]", "face_offset": " [m]", "base_step": " [rad]"}


def error_plot(rows, path) -> Path:
    """``errors.png``: error % against each swept setting (one panel each), one line per object and
    combination of the other settings (colour per object); failures are left out.  Without a swept
    setting: the error per object."""
    plt = _plt()
    ok = [r for r in rows if r["status"] == "ok"]
    keys = [k for k in swept_keys(rows)]
    objects = sorted({r["object"] for r in rows})
    colour = {o: plt.get_cmap("tab10")(i % 10) for i, o in enumerate(objects)}
    n = max(1, len(keys))
    fig, axes = plt.subplots(1, n, figsize=(4.5 * n, 3.8), squeeze=False)
    if not keys:
        ax = axes[0][0]
        for i, o in enumerate(objects):
            e = [r["percent_error"] for r in ok if r["object"] == o]
            ax.bar(i, e[0] if e else 0.0, color=colour[o])
        ax.set_xticks(range(len(objects)), [_short(o) for o in objects], rotation=30, fontsize=7)
        ax.set_ylabel("error [%]")
    for ax, key in zip(axes[0], keys):
        vals = sorted({json.dumps(_value(r, key)) for r in rows})
        decoded = [json.loads(v) for v in vals]
        numeric = _numeric(decoded)
        pos = {v: (json.loads(v) if numeric else i) for i, v in enumerate(vals)}
        groups: dict = {}
        for r in ok:
            others = {k: _value(r, k) for k in swept_keys(rows) if k != key}
            groups.setdefault((r["object"], json.dumps(others, sort_keys=True)), []).append(r)
        seen = set()
        for (obj, _), rs in sorted(groups.items()):
            rs = sorted(rs, key=lambda r: pos[json.dumps(_value(r, key))])
            x = [pos[json.dumps(_value(r, key))] for r in rs]
            y = [r["percent_error"] for r in rs]
            ax.plot(x, y, "o-", color=colour[obj], lw=1, ms=4, alpha=0.8,
                    label=None if obj in seen else _short(obj))
            seen.add(obj)
        if not numeric:
            ax.set_xticks(range(len(vals)), [str(v) for v in decoded], rotation=30, fontsize=7)
        ax.set_xlabel(key + _UNITS.get(key, ""))
        ax.set_ylabel("error [%]")
        ax.grid(alpha=0.3)
    if keys:
        axes[0][0].legend(fontsize=7)
    fig.suptitle("error against each swept setting")
    fig.tight_layout()
    return _save(fig, path)


def thumbnail(folder: Path, row, path: Path) -> Path | None:
    """The estimate of ``row`` coloured by its signed distance to the truth (PNG at ``path``);
    None when the run stored no estimate (a failure) or its files are missing."""
    if row["status"] != "ok" or not row["run_dir"] or not row["truth"]:
        return None
    run_dir, truth_path = folder / row["run_dir"], folder / row["truth"]
    report = json.loads(row["report"])
    planar = report.get("mode") == "planar"
    est_path = run_dir / ("estimate_polygon.json" if planar else "estimate.stl")
    if not est_path.is_file() or not truth_path.is_file():
        return None
    truth = trimesh.load_mesh(truth_path)
    if planar:  # the polygon against the true section at the arm's plane, as the run scored it

        est = Polygon(json.loads(est_path.read_text(encoding="utf-8")))
        truth = planar_truth(truth, float(report["section_z_m"]))
    else:
        est = trimesh.load_mesh(est_path)
    return signed_distance_figure(est, truth, path, title=f"{_short(row['object'])}: {row['percent_error']:.2f} %",
                                  thumbnail=True)


def _html(rows, header, table, thumbs: dict, plot_name: str) -> str:
    e = html.escape
    out = ["<!DOCTYPE html>", "<html><head><meta charset='utf-8'><title>explore3d sweep report</title>",
           "<style>body{font-family:sans-serif;margin:1em}table{border-collapse:collapse;font-size:13px}"
           "td,th{border:1px solid #ccc;padding:3px 6px;text-align:right}td.l{text-align:left}"
           "tr.failed{background:#fdd}</style></head><body>",
           "<h1>explore3d sweep report</h1>",
           f"<p>{len(rows)} runs, {sum(r['status'] == 'ok' for r in rows)} ok, "
           f"{sum(r['status'] != 'ok' for r in rows)} failed.  Error: volume (3D) or area (planar) symmetric "
           "difference / true size, %.  Thumbnails: the estimate coloured by its signed distance to the true "
           "surface, mm (red: outside the truth, blue: inside).</p>",
           f"<p><img src='{e(plot_name)}' alt='error against each swept setting'></p>",
           "<table><tr>" + "".join(f"<th>{e(h)}</th>" for h in header) + "<th>estimate vs truth</th></tr>"]
    for r, row in zip(rows, table):
        cells = _cells(header, row)
        cells[0] = _short(cells[0])
        tds = "".join(f"<td class='l'>{e(c)}</td>" if h in ("object", "reason", "key", "status") else f"<td>{e(c)}</td>"
                      for h, c in zip(header, cells))
        img = thumbs.get(r["key"])
        tds += f"<td><img src='{e(img)}' width='240'></td>" if img else "<td></td>"
        out.append(f"<tr class='{e(r['status'])}'>{tds}</tr>")
    out += ["</table>", "</body></html>"]
    return "\n".join(out) + "\n"


def write_sweep_report(folder, out=None, thumbnails: bool = True) -> list[Path]:
    """Write the report of the sweep in ``folder`` into ``out`` (default ``folder/report``);
    returns the paths written (report.md first).  ``folder`` is only read (its database opened
    read-only, :func:`explore3d.app.sweep.read_rows`).  Raises ValueError (one line) for a folder
    without a sweep, a ``sweep.db`` that is not a sweep's, or an ``out`` that cannot be written
    (checked before anything is written)."""


    folder = Path(folder)
    rows = read_rows(folder)
    if not rows:
        raise ValueError(f"the sweep in {folder} has no stored runs yet; run 'explore3d sweep ... --out {folder}'")
    out = folder / "report" if out is None else Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".write-test.", dir=out)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ValueError(f"cannot write the report into {out} ({exc.strerror or exc}); pass --out a writable "
                         "folder") from None
    header, table = report_table(rows)
    files = [atomic_write_text(out / "report.md", _markdown(rows, header, table)),
             atomic_write_text(out / "report.csv", _csv(header, table)),
             error_plot(rows, out / "errors.png")]
    thumbs = {}
    if thumbnails:
        for r in rows:
            rel = f"thumbs/{r['key']}.png"
            if (out / rel).is_file() or thumbnail(folder, r, out / rel) is not None:
                thumbs[r["key"]] = rel
    files.append(atomic_write_text(out / "report.html", _html(rows, header, table, thumbs, "errors.png")))
    return files
