"""``explore3d run ... --rerun run.rrd`` (issue 26, item 3): a 3D recording of the run for the rerun
viewer, read back with rerun's own reader (``rerun.chunk.RrdReader``).  The optional ``viz`` extra:
without rerun-sdk, ``--rerun`` is refused before the run with one line naming the fix."""
from __future__ import annotations

import json
import re
import sys
from collections import defaultdict

import numpy as np
import pytest

from explore3d.app.cli import main

SMALL_RUN = ["--directions", "24", "--offsets", "1", "--angles", "1", "--attempts", "1", "--probes", "1",
             "--fingers", "0", "--no-pictures", "--jobs", "1"]


def _no_run(monkeypatch):
    import explore3d.app.report as report

    def ran(*args, **kwargs):
        raise AssertionError("--rerun was not refused before the run")

    monkeypatch.setattr(report, "run_and_report", ran)


def test_missing_rerun_is_refused_before_the_run(tmp_path, capsys, monkeypatch):
    """No rerun-sdk: exit 2, one line naming ``pip install -e ".[viz]"``, nothing written."""
    _no_run(monkeypatch)
    monkeypatch.setitem(sys.modules, "rerun", None)  # `import rerun` raises ImportError
    out = tmp_path / "o"
    assert main(["run", "cube", "--out", str(out), "--rerun", str(out / "run.rrd")]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("explore3d: error: --rerun needs rerun-sdk"), err
    assert 'pip install -e ".[viz]"' in lines[0]
    assert not out.exists()


def test_recording_path_checks(tmp_path):
    from explore3d.app.rerun_view import check_recording_path

    assert check_recording_path(tmp_path / "a.rrd") == tmp_path / "a.rrd"
    assert check_recording_path(tmp_path / "new" / "a.rrd", out=tmp_path / "new") == tmp_path / "new" / "a.rrd"
    with pytest.raises(FileNotFoundError, match="does not exist"):
        check_recording_path(tmp_path / "new" / "a.rrd")
    with pytest.raises(ValueError, match=r"\.rrd"):
        check_recording_path(tmp_path / "a.rerun")
    (tmp_path / "d.rrd").mkdir()
    with pytest.raises(ValueError, match="folder"):
        check_recording_path(tmp_path / "d.rrd")


def test_contact_colour_scale():
    """viridis from 0 (dark purple) to the largest value (yellow); NaN grey."""
    from explore3d.app.rerun_view import contact_colours

    rgb, top = contact_colours([0.0, 1.0, 2.0, np.nan])
    assert top == 2.0 and rgb.dtype == np.uint8 and rgb.shape == (4, 3)
    assert tuple(rgb[0]) == (68, 1, 84) and tuple(rgb[2]) == (253, 231, 37) and tuple(rgb[3]) == (150, 150, 150)


def _read(path):
    """entity path -> list of (record batch, is static) of every chunk of the file's one recording."""
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    assert len(reader.recordings()) == 1
    chunks = defaultdict(list)
    for c in reader.stream():
        chunks[c.entity_path].append((c.to_record_batch(), c.is_static))
    return chunks


def _column(chunks, entity, suffix):
    """Every row's value of the column ending in ``suffix`` of ``entity`` (pylist), with its wrap (None: static)."""
    rows = []
    for rb, static in chunks[entity]:
        names = [n for n in rb.schema.names if n.endswith(suffix)]
        if not names:
            continue
        wraps = rb.column("wrap").to_pylist() if "wrap" in rb.schema.names else [None] * rb.num_rows
        rows += list(zip(wraps, rb.column(names[0]).to_pylist()))
    return sorted(rows, key=lambda r: -1 if r[0] is None else r[0])


@pytest.mark.slow
def test_run_writes_a_rerun_recording(tmp_path, capsys):
    """A small 3D run with one round of probes, recorded: the file opens with rerun's reader and
    holds the truth, the estimate after each round (the first one the very estimate the probes
    were aimed at: its volume is the report's), the arm's links per wrap, the detections, every
    hull point of points.ply once (at its own wrap), and the swept free space."""
    pytest.importorskip("rerun")
    from explore3d import ArmSpec, write_arm_urdf
    from explore3d.app.export import read_points_ply
    from explore3d.reconstruction.freespace import is_free, load_swept

    spec = ArmSpec(name="small16", n_links=16, link_length=0.02)
    arm = write_arm_urdf(spec, tmp_path / "small16.urdf")
    out = tmp_path / "run"
    rrd = out / "run.rrd"  # in the --out folder, which the run creates
    assert main(["run", "cube", "--out", str(out), "--arm", str(arm), *SMALL_RUN, "--rerun", str(rrd)]) == 0
    assert f"3D recording: {rrd}" in capsys.readouterr().out
    report = json.loads((out / "report.json").read_text())
    assert not any(p.name.startswith(".") for p in out.iterdir())  # no temporary left
    chunks = _read(rrd)
    entities = set(chunks)
    for e in ("/world/truth", "/world/estimate", "/world/arm/links", "/world/arm/base", "/legend"):
        assert e in entities, sorted(entities)
    for group in ("contacts", "detections", "free_space", "contact_normals"):
        assert any(e.startswith(f"/world/{group}/wrap_") for e in entities), group

    # the truth: static, the cube's 8 corners within its 80 mm
    ((_, truth),) = _column(chunks, "/world/truth", "vertex_positions")
    assert np.ptp(np.array(truth), axis=0) == pytest.approx([0.08] * 3, abs=1e-6)

    # every hull point (points.ply) once, at the wrap it came from, coloured
    P, props = read_points_ply(out / "points.ply", with_properties=True)
    logged, at = [], []
    for e in sorted(e for e in entities if e.startswith("/world/contacts/wrap_")):
        rows = _column(chunks, e, "Points3D:positions")
        assert len(rows) == 1 and rows[0][0] == int(re.search(r"wrap_(\d+)", e).group(1))
        logged += rows[0][1]
        at += [rows[0][0]] * len(rows[0][1])
    assert len(logged) == len(P) == report["n_points"] > 0
    order = np.lexsort(np.round(P, 7).T)
    assert np.allclose(np.array(logged)[np.lexsort(np.round(np.array(logged), 7).T)], P[order], atol=1e-6)
    assert sorted(at) == sorted(props["wrap"].tolist())

    # the arm: one row per wrap on the wrap timeline, 16 boxes of 20 mm x width x height
    links = _column(chunks, "/world/arm/links", "half_sizes")
    assert [w for w, _ in links] == list(range(report["n_wraps"]))
    assert np.allclose(np.array(links[0][1]), [[0.01, spec.link_width / 2, spec.link_height / 2]] * 16)
    n_detections = sum(len(r[1]) for e in entities if e.startswith("/world/detections/")
                       for r in _column(chunks, e, "Points3D:positions"))
    assert n_detections == report["n_contacts"] > 0  # one per joint sweep that ended in a detected contact

    # the estimate after each round: the planned wraps', whose volume the probe round saw, then the run's
    est = _column(chunks, "/world/estimate", "volume_m3")
    (probe,) = report["probe_rounds"]
    planned = report["n_wraps"] - probe["wraps"]
    assert [w for w, _ in est] == [planned - 1, report["n_wraps"] - 1]
    assert est[0][1][0] == pytest.approx(probe["volume_m3"], rel=1e-9)
    assert est[1][1][0] == pytest.approx(report["estimate_size"], rel=1e-9)

    # the free space: every point lies in the space the run's free_space.npz holds as swept
    F = np.vstack([np.array(r[1]) for e in entities if e.startswith("/world/free_space/")
                   for r in _column(chunks, e, "Points3D:positions")])
    assert len(F) > 100
    assert is_free(load_swept(out / "free_space.npz"), F).all()
