"""Explore an object in the simulated world: the exploration loop of
:mod:`explore3d.strategy.explore` run on PyBullet workcells built around a mesh.

The mesh goes to the simulator only (the world); the strategy is told what a robot would be: the
rough centre and bounding radius of the object, the table's height, its own contact band.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from explore3d.arm.urdf import load_arm
from explore3d.core.settings import SimConfig
from explore3d.strategy.explore import Exploration, ExploreConfig, explore_robots, rough_bound, takes_phase
from explore3d.world.band import cached_band
from explore3d.world.scene import SceneSetup, settle_scene
from explore3d.world.sim import ArmSimulation

__all__ = ["SimWorkcells", "explore"]


@dataclass(frozen=True, eq=False)
class SimWorkcells:
    """A picklable factory of simulated workcells: each call opens a new
    :class:`~explore3d.world.sim.ArmSimulation` of the arm ``spec`` with the object (``vertices``
    (v, 3) metres, world frame, and ``faces`` (f, 3) int; None: free space, or the resting object
    of ``setup``), physics ``sim`` and the settled scene ``setup`` (None: the paper's idealised
    world)."""

    spec: object
    vertices: np.ndarray | None
    faces: np.ndarray | None
    sim: SimConfig
    setup: SceneSetup | None = None

    def __call__(self) -> ArmSimulation:
        return ArmSimulation(self.spec, self.vertices, self.faces, self.sim, self.setup)


def explore(mesh, arm="default", config: ExploreConfig = ExploreConfig(), centre=None, radius=None,
            progress=None, *, setup=None, after_wrap=None) -> Exploration:
    """Explore ``mesh`` (a closed trimesh, metres, world frame) with ``arm`` (name, URDF path or
    ArmSpec) in the simulated world and return what the wraps gathered
    (:func:`explore3d.strategy.explore.explore_robots` on :class:`SimWorkcells`).

    Args:
        centre, radius: the rough location (3,) and bounding radius (m) the robot is told;
            default: :func:`~explore3d.strategy.explore.rough_bound` of the object (the mesh
            itself is never given to the robot; in a scene other than the ideal one, of the object
            as it rests).
        progress: None, or a callable ``progress(done, total)`` called after each wrap.
        setup: the settled scene (:func:`explore3d.world.scene.settle_scene`) when ``config.scene`` is not
            the ideal one; None: settled here.  The robot is told its table height only.
        after_wrap: the evaluation's hook ``after_wrap(index, world)``, called with index -1 when a
            world is ready and after each wrap with its index, with the
            :class:`~explore3d.world.sim.ArmSimulation` it runs in (a persistent world, or one job; e.g.
            :class:`explore3d.world.scene.SceneWatch`); never seen by the exploration.
    """
    t0 = time.perf_counter()
    spec = load_arm(arm)
    if setup is None and not config.scene.ideal:
        setup = settle_scene(mesh, config.scene, spec, config.sim)
    truth = mesh if setup is None else setup.truth
    c0, r0 = rough_bound(truth.vertices)
    centre = c0 if centre is None else np.asarray(centre, float)
    radius = r0 if radius is None else float(radius)
    table_z = None if setup is None else setup.table_z
    if progress is not None and takes_phase(progress):
        progress(0, None, "contact band")  # measured once per arm and setting, then cached
    band = cached_band(spec, config.control, config.sim, config.sensors, config.mode == "planar")
    band_s = time.perf_counter() - t0
    persistent = setup is not None and config.scene.persistent
    if persistent:  # one world for the run: the resting object comes from the settled scene
        workcells = SimWorkcells(spec, None, None, config.sim, setup)
    else:
        workcells = SimWorkcells(spec, np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64),
                                 config.sim, setup)
    return explore_robots(workcells, spec, config, band, centre, radius, progress, table_z=table_z,
                          persistent=persistent, after_wrap=after_wrap, band_s=band_s)
