"""Default parameter values shared by the library, the command line and the scripts (no imports,
so the command line reads them without loading numpy).  One value per concept."""

#: The inverse hull's default coarseness ``a`` everywhere except the paper replica.  Measured on
#: the default arm's 3D cube runs and in ``scripts/studies/parameter_study.py``: smaller ``a`` follows
#: corners tighter; 0.05 cuts a dense square's corners by 0.4 % of its area (explore3d.geometry.hull).
DEFAULT_A = 0.05

#: The largest inverse-hull coarseness accepted.  The paper tried 0.05-0.5; at a = 10 the hull of
#: r**-a already keeps only the points nearest the centre along each ray, and r**-a overflows
#: float64 (1.8e308) once a * log10(1/r) > 308: for a <= 10 only below r = 1e-30 m, so no real
#: point set overflows (a = 300 did, for r = 0.04 m, after a whole exploration).
MAX_A = 10.0

#: The paper's ``a`` (section IV), used only by its replica (:mod:`explore3d.app.table1`,
#: :func:`explore3d.world.simulated.simulated_case`).
PAPER_A = 0.2

#: The reconstruction estimators' names (:data:`explore3d.reconstruction.estimators.ESTIMATORS`; ``explore3d
#: reconstruct --estimator``), the paper's inverse hull first.
ESTIMATOR_NAMES = ("inverse-hull", "convex-carved", "multi-centre", "implicit")

#: The named scenes of ``explore3d run --scene`` (:meth:`explore3d.core.settings.SceneConfig.named`): the
#: paper's idealised world (the default) and the object resting on a table.
SCENE_NAMES = ("ideal", "table")
