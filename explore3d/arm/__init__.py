"""Floor 1, the arm's own model: its spec and URDF, forward kinematics and Jacobians, the distances
between its own bodies and its workspace above a plane.  Pure functions on numpy arrays."""
