"""Floor 2, pure geometry: the inverse convex hull, the error measures, the wrap directions,
signed distances (to meshes and the arm's link boxes) and a mesh's bodies."""
