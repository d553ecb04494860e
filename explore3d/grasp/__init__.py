"""Grasps planned on a mesh: a parallel-jaw gripper's geometry and an antipodal sampler (pure
geometry; executing a grasp is evaluation and lives in :mod:`explore3d.world.grasping`)."""
