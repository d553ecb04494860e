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

#: Distance in metres within which a simulated link point counts as on an object's surface
#: (explore3d.world.simulated).  Link end points are computed from boundary points of ~0.1 m objects
#: in float64 (error ~1e-17 m, a few ulps); 1 nm is a wide margin yet far below any feature.
SURFACE_ATOL_M = 1e-9

#: Relative volume agreement of a mesh written to binary STL and read back: STL stores
#: float32 coordinates (relative rounding 6e-8 per coordinate, ~3 of them per volume term).
STL_FLOAT32_RTOL = 1e-6

#: Issue target for the 3D inverse hull of dense surface samples: volume error below 3 % of the
#: true volume (at a suitable ``a``; explore3d.geometry.hull).  A requirement, not a measured value.
INVERSE_HULL_VOLUME_RTOL = 0.03

#: Relative agreement of float64 volumes/areas computed two ways (exact answer vs boolean
#: intersection; a shape vs its rigidly moved copy).  float64 rounding is ~1e-16 per operation;
#: sums over ~1e4 triangles and rotated coordinates stay below ~1e-12; 1e-9 is a wide margin
#: (float32, as in trimesh's manifold wrapper, would give ~1e-7 and fail it).
FLOAT64_GEOMETRY_RTOL = 1e-9

#: Points of a hull input closer than this many metres are merged into one before the hull
#: (explore3d.geometry.hull.inverse_hull).  Measured: the default arm's 96 wraps around the cube give 249
#: point pairs within 1 um (none within 1 nm): where a joint is barely bent, the corner samples of
#: two neighbouring links coincide up to ~W/2 x the joint angle.  Kept apart they become sliver
#: triangles with edges of ~1e-8 m, which the export formats (OBJ: 8 decimals, STL/GLB: float32,
#: ~4e-9 m at 0.1 m) and the loaders' vertex merging (trimesh: 1e-8) collapse into degenerate faces
#: and edges shared by four faces.  1 um is 100 x those precisions and 5000 x below the 5 mm
#: spacing of the link samples.
MERGE_DISTANCE_M = 1e-6

#: A separate piece of an estimate below this fraction of its main body's volume is a sliver
#: (explore3d.geometry.bodies.one_body).  Measured: the default cube's carved estimate left pieces of 3e-7
#: and 1e-8 of its volume (0.16 and 0.006 mm^3 of 5.1e5) where the smoothed cutting volume grazed
#: it; 1e-3 (0.5 cm^3, an 8 mm cube, for the 80 mm cube) is 3000 x above those and below any
#: part a 5 mm-link arm resolves on its own.  Larger pieces are kept with a warning: free space or
#: the table cut severed a real part, and dropping it could lose half the object.
SLIVER_RTOL = 1e-3
