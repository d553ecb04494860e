"""The fast paths of issue 12, item 4 ("Speed") compute exactly what the general code computes
(bit-identical: the chain's contact dynamics turn a 1e-16 change into different detections)."""
import numpy as np
import pytest
from scipy.optimize import nnls

from explore3d.arm.urdf import load_arm
from explore3d.geometry.directions import spatial_wrap_poses
from explore3d.arm.kinematics import gravity_torques, link_transforms
from explore3d.feeling.localise import _nnls


def _gravity_torques_general(spec, q, T_world_base, gravity):
    """The 3D form through link_transforms and np.cross (the code before the fast path)."""
    T = link_transforms(spec, q, T_world_base)
    com = T[:, :3, 3] + T[:, :3, 0] * (spec.link_length / 2.0)
    f = spec.link_mass * np.asarray(gravity, dtype=np.float64)
    z = T[0, :3, 2]
    tail_m = np.cumsum((np.cross(com, f) @ z)[::-1])[::-1]
    tail_f = np.arange(spec.n_links, 0, -1)[:, None] * f[None, :]
    return tail_m - np.cross(T[:, :3, 3], tail_f) @ z


@pytest.mark.parametrize("arm", ["default", "paper"])
def test_gravity_torques_bit_identical_to_general_form(arm):
    spec = load_arm(arm)
    rng = np.random.default_rng(12)
    poses = spatial_wrap_poses([0.01, -0.02, 0.03], 0.07, spec.link_width, 12, 1, 2)
    for pose in poses:
        for _ in range(20):
            q = rng.uniform(spec.joint_lower, spec.joint_upper, spec.n_links) * rng.integers(0, 2, spec.n_links)
            g = rng.normal(size=3) * 5
            a = gravity_torques(spec, q, pose.T_world_base, g)
            b = _gravity_torques_general(spec, q, pose.T_world_base, g)
            assert np.array_equal(a, b)


def test_raw_nnls_same_numbers_as_scipy():
    rng = np.random.default_rng(3)
    for _ in range(300):
        k = int(rng.integers(1, 9))
        A, b = rng.normal(size=(24 + k, k)), rng.normal(size=24 + k)
        A0, b0 = A.copy(), b.copy()
        x1, r1 = nnls(A, b, maxiter=50 * k)
        x2, r2 = _nnls(A, b, 50 * k)
        assert np.array_equal(x1, x2) and r1 == r2
        assert np.array_equal(A, A0) and np.array_equal(b, b0)  # inputs untouched
