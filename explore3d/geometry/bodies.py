"""One closed body: the slivers a cut leaves beside an estimate are dropped (pure geometry).

The inverse hull is one star-shaped body, but cutting the swept free space out of it
(:mod:`explore3d.reconstruction.carve`) or cutting it at a table's plane (:mod:`explore3d.reconstruction.tabletop`) can leave
separate pieces: slivers of a fraction of a cubic millimetre where the cutting volume's smoothed
surface grazes the estimate's (measured: the default cube's carved estimate had pieces of 0.16
and 0.006 mm^3 beside its 5.1e5 mm^3 body, so the exported estimate reloaded as three bodies).
:func:`one_body` drops every piece below a stated fraction of the main body's volume and returns
what it dropped so the caller can report it.  A larger piece (free space that really severed a part
of the estimate) is kept, with a warning: dropping it could throw away half of the object.
Volumes in m^3 when the mesh is in metres.
"""
from __future__ import annotations

import logging

import numpy as np
import trimesh

from explore3d.core.tolerances import SLIVER_RTOL

__all__ = ["one_body"]

log = logging.getLogger(__name__)


def one_body(mesh, sliver_rtol: float = SLIVER_RTOL) -> tuple[object, tuple[float, ...]]:
    """``mesh`` (closed trimesh) without its slivers, and the volumes (m^3, > 0) of those dropped.

    The connected surfaces of ``mesh`` are split apart; the one of largest signed volume is the
    body.  Every other surface (a separate piece, or an inward-wound one: a cavity) whose volume is
    below ``sliver_rtol`` times the body's is a sliver and is dropped (logged at INFO); a larger one
    is kept and logged as a WARNING (the estimate then has more than one body).  ``mesh`` itself is
    returned when it has one surface or no sliver.
    """
    if isinstance(sliver_rtol, bool) or not (isinstance(sliver_rtol, (int, float)) and 0 <= sliver_rtol < 1):
        raise ValueError(f"sliver_rtol must be a number in [0, 1); got {sliver_rtol!r}")
    if mesh.body_count <= 1:
        return mesh, ()
    parts = mesh.split(only_watertight=False)
    volumes = np.array([float(p.volume) for p in parts])
    main = int(np.argmax(volumes))
    floor = sliver_rtol * volumes[main]
    small = np.abs(volumes) < floor
    small[main] = False
    dropped = tuple(float(v) for v in np.abs(volumes[small]))
    big = [float(v) for i, v in enumerate(volumes) if i != main and not small[i]]
    if big:
        log.warning("estimate: %d piece(s) besides the body (%s m^3, the body %.3g m^3): the free space or the "
                    "table cut severed them; kept", len(big), ", ".join(f"{v:.3g}" for v in big), volumes[main])
    if not dropped:
        return mesh, ()
    log.info("estimate: dropped %d sliver(s) of %.3g m^3 in all (each below %.2g of the body's volume)",
             len(dropped), sum(dropped), sliver_rtol)
    keep = [p for p, s in zip(parts, small) if not s]
    if len(keep) == 1:
        return keep[0], dropped

    return trimesh.util.concatenate(keep), dropped
