"""The world's settings every floor shares: :class:`SimConfig` (physics) and :class:`SceneConfig`
(which idealisations of the world hold).  Plain frozen dataclasses, validated on creation; the
world that uses them is :mod:`explore3d.world` (an exploration carries them in its
:class:`~explore3d.strategy.explore.ExploreConfig` and reads only the timestep and the table's
clearance)."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from explore3d.core.defaults import SCENE_NAMES
from explore3d.core.validate import check_field


@dataclass(frozen=True)
class SimConfig:
    """Physics settings (SI).

    Attributes:
        timestep: physics step, s.
        solver: "dantzig" (PyBullet's direct MLCP solver: stiff, held joints stay put; it drops
            rolling and spinning friction, which the world then applies itself:
            :mod:`explore3d.world.support`) or "si" (the default
            sequential-impulse solver, soft for long chains).
        position_gain, velocity_gain: PyBullet POSITION_CONTROL motor gains (dimensionless,
            they scale the motor constraint's error reduction).
        gravity: gravity vector in the world frame, m/s^2.
        friction: Coulomb friction coefficient between the links and the object.  0 by default:
            measured on the 80 mm cube, PyBullet's friction made held links stick-slip against the
            surface (contact forces jumping between 0 and ~15 N from step to step), which read as
            false contacts; with frictionless contact the wrap is clean.
        collision_margin: PyBullet collision margin of the object and of the base block, m
            (``changeDynamics(collisionMargin=...)``; PyBullet leaves the links of a multibody at its
            1 mm whatever is asked, measured with getDynamicsInfo); None keeps PyBullet's defaults, which
            leave touching faces about 1 mm outside a triangle mesh.  Default 0.3 mm: measured on
            every built-in object (BENCHMARKS.md, "Thin contact margin"), touching faces then
            sit about 0.2 mm out; 0.1 mm and thinner let links sink up to 2-3 mm into the
            sphere's mesh, and 0 let the chain blow up.
        self_collision: the arm collides with itself (PyBullet's ``URDF_USE_SELF_COLLISION``):
            a link with every other link and with the base block, except the bodies a joint
            connects (link i with link i + 1, link 0 with the base), whose boxes meet at the joint
            and overlap on the inner side of a bent joint at every angle (by the model: 5.7 mm at
            the upper limit, 1.9 mm at the lower; link 0 and the base block 7.3 and 0.9 mm; with
            ``URDF_USE_SELF_COLLISION_INCLUDE_PARENT`` PyBullet reports every neighbouring pair
            touching even with the arm straight).  PyBullet excludes
            those parent-child pairs by default (``URDF_USE_SELF_COLLISION_EXCLUDE_PARENT`` adds
            nothing: measured, the same pairs collide with and without it; only
            ``URDF_USE_SELF_COLLISION_INCLUDE_PARENT`` would collide them).  A link's grandparent
            is not excluded: with two neighbouring joints near the upper limit link i + 2 folds
            into link i (default arm: they touch from 1.9 rad on both joints; at 2 rad PyBullet and
            the model overlap them by 3.6 mm), which a real arm of these boxes would feel.  The exploration tells such a touch from the object's by
            the arm's own kinematics (:mod:`explore3d.arm.selfcontact`).  Measured with the Dantzig
            solver: a link lying on the base block now and then flips off it within one step
            (small16's tip: 0.417 rad in one step, the model's distance 0 -> 11 mm; 9 such flips in
            253 base-link contact steps of 6 default-arm wraps of the cube, against 31 in 10943
            arm-object contact steps).  Re-running that step with ERP 0.05 or 0.01, 200 solver
            iterations, split impulse or a 1 mm contact breaking threshold gives the same flip;
            the SI solver none (0.013 rad), PGS 0.023 rad, 4 substeps 0.35 rad; the base block as a
            separate static body instead of the arm's base link flips too (18 in 485).  The band
            calibration and the controller therefore judge a detection by the sweep's last
            readings, not its own (:data:`explore3d.strategy.encircle.SELF_CONTACT_WINDOW_STEPS`).  False: links pass through
            each other (the behaviour before self-collision existed).
        mass_error: the simulated arm's link masses and inertias differ from its model (the
            controller's) by a factor ``1 + e`` per link, ``e`` drawn uniformly from
            ``[-mass_error, mass_error]`` with ``mass_seed`` (:func:`mass_scales`;
            0: the model is exact).  The contact band is measured on this arm (as a robot measures
            its own free motion), the gravity feed-forward and the localisation use the model.
        mass_seed: seed of the mass error.
        global_cfm: PyBullet's constraint force mixing on every constraint
            (``setPhysicsEngineParameter(globalCFM=...)``, dimensionless), or None for PyBullet's
            default 0.  The Dantzig solver builds one MLCP of every constraint in the world; a
            free body resting on a table with friction makes it degenerate (four corner contacts
            and their friction rows for three degrees of freedom), the solve fails and PyBullet
            falls back to a few sequential-impulse iterations for the whole world, the arm's joint
            motors included.  Measured (``scripts/studies/physics_study.py``): the default arm swinging in
            free space beside a resting 80 mm cube tracked its reference within 313 mrad and read
            torques of up to 2.1 N m, against 3.9 mrad and 0.09 N m with no object; with 1e-7, 1e-6 or
            1e-5 the torques are the empty world's, bit for bit.  The table scene sets 1e-6
            (:func:`~explore3d.world.scene.scene_explore_config`).
    """

    timestep: float = 1.0 / 240.0
    solver: str = "dantzig"
    position_gain: float = 0.3
    velocity_gain: float = 1.0
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    friction: float = 0.0
    collision_margin: float | None = 3.0e-4
    self_collision: bool = True
    mass_error: float = 0.0
    mass_seed: int = 0
    global_cfm: float | None = None

    def __post_init__(self):
        if self.solver not in ("dantzig", "si"):
            raise ValueError(f"SimConfig.solver must be 'dantzig' or 'si'; got {self.solver!r}")
        check_field(self, "timestep", 0, "s", strict=True, hi=0.05)
        check_field(self, "position_gain", 0, strict=True)
        check_field(self, "velocity_gain", 0)
        check_field(self, "friction", 0)
        check_field(self, "mass_error", 0, hi=0.5)
        check_field(self, "mass_seed", 0, integer=True)
        if self.global_cfm is not None:
            check_field(self, "global_cfm", 0, "(dimensionless, or None)", hi=1.0)
        if not isinstance(self.self_collision, bool):
            raise ValueError(f"SimConfig.self_collision must be True or False; got {self.self_collision!r}")
        if self.collision_margin is not None:
            check_field(self, "collision_margin", 0, "m (or None)", hi=0.01)
        g = np.asarray(self.gravity, dtype=float) if np.ndim(self.gravity) == 1 else None
        if g is None or g.shape != (3,) or not np.isfinite(g).all():
            raise ValueError(f"SimConfig.gravity must be 3 finite numbers, m/s^2, world frame; got {self.gravity!r}")


@dataclass(frozen=True)
class SceneConfig:
    """Which idealisations of the world hold (SI units).

    Attributes:
        table: a static table under the object, its top at the object's lowest point as given;
            the robot is told its height.  False: no table, the object floats.
        resting: the object is a free rigid body resting on the table under gravity, with mass
            ``density`` times its volume (needs ``table``).  False: the object is fixed in place.
        density: of a resting object, kg/m^3 (default 500: a light wood or a plastic part).
        friction: Coulomb coefficient between the arm's links and the object; None: the physics
            settings' :attr:`~explore3d.core.settings.SimConfig.friction` (0 by default).
        table_friction: Coulomb coefficient between the object and the table.
        least_mass_kg: the lightest object the robot expects to meet, kg (told to the robot): the
            table scene's sweeps press at most half the static friction that holds it
            (:func:`explore3d.strategy.encircle.force_budget_n`; default 0.1 kg at friction 0.5:
            0.25 N).
        rolling_friction_m: rolling resistance between the object and the table, m: the lever
            arm of the normal force that resists rolling (PyBullet's ``rollingFriction``: the
            resisting torque is at most this times the normal force).  PyBullet's default 0 lets
            a ball roll for ever.  The table scene's 1 mm: wood on wood 1.5 mm, a polymer on
            steel 0.8 mm (engineering tables of the lever arm of rolling friction).
        spinning_friction_m: resistance to spinning about the contact normal, m (PyBullet's
            ``spinningFriction``, same units): about the friction coefficient times the contact
            patch's radius; the table scene's 0.5 mm (friction 0.5, a patch of about 1 mm).
        restitution: of the object (0: contacts do not bounce).
        persistent: one world for the whole run, the wraps in sequence (the object stays where
            the arm left it); False: every wrap starts from the settled scene (wraps may then run
            in parallel).
        settle_time: at most this long, s, for the object to come to rest before exploring.
        table_clearance: the arm's planned motion keeps every link this far above the table, m.
        contact_erp: the world's contact error reduction (PyBullet ``contactERP``) with a resting
            object (None, the default: PyBullet's 0.2).  Measured on the cube resting on the table
            (gentle sweeps, frictionless links, Dantzig solver, 5 wraps): at 0.2 a link striking it was pushed out
            of the 1 mm contact margin within one step and kicked the cube to 126 mm/s (4.2 mm, 3.9
            degrees of drift), at 0.02 the drift was 0.5 mm, 0.4 degrees; but at 0.02 the joints
            tracked their references more loosely and every joint's sweep fired in free space
            (3 of the first 3 joints of a wrap, against 0 of 3 at 0.2).
        redo_moved: in a persistent world, a wrap after which the object seems to have moved
            (:mod:`explore3d.strategy.motion`) is run once more from the same pose.
        register_moved: on a table, the points and swept space gathered after such a motion are
            carried back onto the estimate of those before it (a planar rigid registration,
            :func:`explore3d.strategy.motion.carry_back`) before the hull; the flagged wraps' own are
            dropped.  Off by default: it needs contacts on the surface, and the table scene's link
            points lie 5-15 mm off it (measured on the table cube: registrations that left the
            RMS at 18 mm; BENCHMARKS.md, "Table scene: force budget").  False: every point is
            hulled where it was touched.
    """

    table: bool = False
    resting: bool = False
    density: float = 500.0
    friction: float | None = None
    table_friction: float = 0.5
    least_mass_kg: float = 0.1
    rolling_friction_m: float = 0.0
    spinning_friction_m: float = 0.0
    restitution: float = 0.0
    persistent: bool = False
    settle_time: float = 3.0
    table_clearance: float = 0.003
    contact_erp: float | None = None
    redo_moved: bool = True
    register_moved: bool = False

    def __post_init__(self):
        for name in ("table", "resting", "persistent", "redo_moved", "register_moved"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"SceneConfig.{name} must be True or False; got {getattr(self, name)!r}")
        if self.resting and not self.table:
            raise ValueError("SceneConfig.resting needs a table to rest on: pass table=True too, or resting=False "
                             "(a fixed object)")
        check_field(self, "density", 0, "kg/m^3", strict=True)
        if self.friction is not None:
            check_field(self, "friction", 0, "(or None)")
        check_field(self, "table_friction", 0)
        check_field(self, "least_mass_kg", 0, "kg", strict=True)
        check_field(self, "rolling_friction_m", 0, "m")
        check_field(self, "spinning_friction_m", 0, "m")
        check_field(self, "restitution", 0, hi=1)
        check_field(self, "settle_time", 0, "s", strict=True)
        check_field(self, "table_clearance", 0, "m")
        if self.contact_erp is not None:
            check_field(self, "contact_erp", 0, "(or None)", strict=True, hi=1)

    @classmethod
    def named(cls, name: str) -> "SceneConfig":
        """``"ideal"``: the floating fixed object of the paper (the default); ``"table"``: the object
        resting on a table, friction 0.5 on the links and the table, rolling and spinning friction of
        real materials (1 mm, 0.5 mm), one persistent world (the
        table scene's 5% model mass error is the physics settings', :func:`explore3d.world.scene.scene_explore_config`)."""
        if name == "ideal":
            return cls()
        if name == "table":
            return cls(table=True, resting=True, friction=0.5, table_friction=0.5, rolling_friction_m=1.0e-3,
                       spinning_friction_m=0.5e-3, persistent=True)
        raise ValueError(f"unknown scene {name!r}; valid: {', '.join(SCENE_NAMES)}")

    @property
    def ideal(self) -> bool:
        """No table, a fixed object, no link friction of its own, a world reset every wrap."""
        return not (self.table or self.resting or self.persistent or self.friction is not None)

    def to_dict(self) -> dict:
        return asdict(self)
