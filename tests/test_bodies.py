"""Tests of explore3d.geometry.bodies.one_body: known answers on boxes, slivers and cavities."""
import logging

import numpy as np
import pytest
import trimesh

from explore3d.geometry.bodies import one_body
from explore3d.reconstruction.carve import carve
from explore3d.core.tolerances import FLOAT64_GEOMETRY_RTOL, SLIVER_RTOL


def _box(extent, centre=(0.0, 0.0, 0.0)):
    return trimesh.creation.box(extent, transform=trimesh.transformations.translation_matrix(centre))


def test_one_surface_comes_back_itself():
    box = _box((0.08, 0.08, 0.08))
    out, dropped = one_body(box)
    assert out is box and dropped == ()


@pytest.mark.parametrize("seed", range(3))
def test_slivers_are_dropped_and_their_volumes_reported(seed):
    rng = np.random.default_rng(seed)
    body = _box((0.08, 0.08, 0.08))
    edges = rng.uniform(1e-4, 5e-4, size=(2, 3))  # 1e-11 to 1.25e-10 m^3: below 1e-3 of 5.1e-4 m^3
    slivers = [_box(e, (0.0445, float(rng.uniform(-0.03, 0.03)), 0.0)) for e in edges]
    out, dropped = one_body(trimesh.util.concatenate([body, *slivers]))
    assert out.body_count == 1 and out.is_watertight
    assert out.volume == pytest.approx(body.volume, rel=FLOAT64_GEOMETRY_RTOL)
    np.testing.assert_allclose(sorted(dropped), sorted(float(np.prod(e)) for e in edges), rtol=FLOAT64_GEOMETRY_RTOL)


def test_a_real_piece_is_kept_with_a_warning(caplog):
    body = _box((0.08, 0.08, 0.08))
    piece = _box((0.02, 0.02, 0.02), (0.1, 0.0, 0.0))  # 1.6e-2 of the body: not a sliver
    with caplog.at_level(logging.WARNING, logger="explore3d.geometry.bodies"):
        out, dropped = one_body(trimesh.util.concatenate([body, piece]))
    assert dropped == () and out.body_count == 2
    assert "severed" in caplog.text


def test_a_cavity_is_kept_and_a_sliver_cavity_filled():
    outer = _box((0.08, 0.08, 0.08))
    cavity = _box((0.02, 0.02, 0.02))
    cavity.invert()
    tiny = _box((1e-4, 1e-4, 1e-4), (0.02, 0.02, 0.02))
    tiny.invert()
    out, dropped = one_body(trimesh.util.concatenate([outer, cavity, tiny]))
    assert out.volume == pytest.approx(outer.volume - 0.02 ** 3, rel=FLOAT64_GEOMETRY_RTOL)
    assert dropped == pytest.approx((1e-12,), rel=FLOAT64_GEOMETRY_RTOL)


def test_the_stated_fraction_decides():
    body = _box((0.1, 0.1, 0.1))  # 1e-3 m^3
    side = (SLIVER_RTOL * 1e-3) ** (1 / 3)
    just_below = _box((0.99 * side,) * 3, (0.2, 0.0, 0.0))
    just_above = _box((1.01 * side,) * 3, (0.2, 0.0, 0.0))
    assert len(one_body(trimesh.util.concatenate([body, just_below]))[1]) == 1
    assert one_body(trimesh.util.concatenate([body, just_above]))[1] == ()
    with pytest.raises(ValueError, match="sliver_rtol"):
        one_body(body, sliver_rtol=1.5)


def test_carving_never_returns_a_sliver():
    """A free slab that grazes a box's corner region leaves, after the smoothing and the boolean,
    no piece below the sliver fraction."""
    from explore3d.reconstruction.freespace import SweptArea

    box = _box((0.04, 0.04, 0.04))
    rng = np.random.default_rng(0)
    for _ in range(4):
        n = 100
        free = rng.uniform(size=(n, n)) < 0.6  # a ragged free area: many small cut pieces
        T = np.eye(4)
        T[2, 3] = rng.uniform(-0.015, 0.015)
        res = carve(box, [SweptArea(T_world_base=T, origin_m=np.full(2, -0.05), pixel_m=1e-3, free=free,
                                    half_height_m=0.003, margin_m=0.0)])
        vols = [abs(p.volume) for p in res.mesh.split(only_watertight=False)]
        assert min(vols) >= SLIVER_RTOL * max(vols)
        assert res.mesh.is_watertight
