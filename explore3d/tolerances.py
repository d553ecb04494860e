"""Numerical tolerances used across explore3d, each with where its value comes from.

Tests import these rather than repeating literals.  Append new constants with a comment;
never change one to make a test pass.
"""

#: Relative tolerance (of the point set's bounding-box diagonal) below which points are
#: treated as collinear (2D) or coplanar (3D). Qhull's own precision is ~1e-13 relative;
#: 1e-9 keeps a wide safety margin while still accepting sub-micrometre features of
#: metre-scale objects.
DEGENERACY_RTOL = 1e-9

#: Forward kinematics agrees with PyBullet's link states to this many metres (issue 3).
FK_ATOL_M = 1e-6
