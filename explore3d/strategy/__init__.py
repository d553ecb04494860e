"""Floor 6, the strategy: encirclement, curl-back, probes, motion flags and the exploration loop.
It runs on the :class:`~explore3d.robot.interface.Robot` it is handed and never imports pybullet
or the simulated world (an import-linter contract in pyproject.toml)."""
