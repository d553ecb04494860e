"""The arm URDF and the numpy forward kinematics, checked against PyBullet's own link states."""
import numpy as np
import pybullet
import pytest

from explore3d.arm.spec import BUILTIN_ARMS, ArmSpec
from explore3d.arm.urdf import load_arm
from explore3d.arm.urdf import arm_urdf, write_arm_urdf
from explore3d.arm.kinematics import link_surface_points, link_transforms
from explore3d.core.tolerances import FK_ATOL_M


def _random_T(rng):
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng.integers(1 << 31)).as_matrix()
    T[:3, 3] = rng.uniform(-0.5, 0.5, 3)
    return T


@pytest.mark.parametrize("name", sorted(BUILTIN_ARMS))
def test_builtin_urdf_loads_and_round_trips(tmp_path, name):
    spec = BUILTIN_ARMS[name]
    path = write_arm_urdf(spec, tmp_path / f"{name}.urdf")
    c = pybullet.connect(pybullet.DIRECT)
    try:
        body = pybullet.loadURDF(str(path), useFixedBase=True, physicsClientId=c)
        assert pybullet.getNumJoints(body, physicsClientId=c) == spec.n_links
    finally:
        pybullet.disconnect(c)
    assert load_arm(path) == spec
    assert load_arm(name) == spec


def test_shipped_urdfs_match_the_generator():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "urdf"
    for name, spec in BUILTIN_ARMS.items():
        assert (root / f"{name}.urdf").read_text() == arm_urdf(spec), f"regenerate urdf/: python scripts/make_arms.py"


@pytest.mark.parametrize("kwargs", [dict(n_links=0), dict(link_length=-0.01), dict(link_mass=0.0),
                                    dict(joint_lower=0.1), dict(name="bad name")])
def test_bad_spec_raises(kwargs):
    with pytest.raises(ValueError):
        ArmSpec(**kwargs)


def test_load_arm_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown arm"):
        load_arm("nonesuch")
    with pytest.raises(ValueError, match="does not exist"):
        load_arm(tmp_path / "missing.urdf")
    (tmp_path / "other.urdf").write_text("<robot name='x'/>")
    with pytest.raises(ValueError, match="has no joints"):  # read by its joints and links: it has none
        load_arm(tmp_path / "other.urdf")


def test_forward_kinematics_matches_pybullet():
    rng = np.random.default_rng(0)
    spec = ArmSpec(name="fk", n_links=7, link_length=0.03)
    c = pybullet.connect(pybullet.DIRECT)
    try:
        import tempfile, os

        fd, path = tempfile.mkstemp(suffix=".urdf")
        os.close(fd)
        write_arm_urdf(spec, path)
        body = pybullet.loadURDF(path, useFixedBase=True, physicsClientId=c)
        os.unlink(path)
        for _ in range(5):
            T = _random_T(rng)
            q = rng.uniform(spec.joint_lower, spec.joint_upper, spec.n_links)
            from scipy.spatial.transform import Rotation

            pybullet.resetBasePositionAndOrientation(body, T[:3, 3].tolist(),
                                                     Rotation.from_matrix(T[:3, :3]).as_quat().tolist(), physicsClientId=c)
            for j, qj in enumerate(q):
                pybullet.resetJointState(body, j, qj, physicsClientId=c)
            ours = link_transforms(spec, q, T)
            for j in range(spec.n_links):
                st = pybullet.getLinkState(body, j, computeForwardKinematics=True, physicsClientId=c)
                pos, quat = np.array(st[4]), st[5]  # URDF link frame, quaternion (x, y, z, w)
                R = np.array(pybullet.getMatrixFromQuaternion(quat)).reshape(3, 3)
                assert np.allclose(ours[j, :3, 3], pos, atol=FK_ATOL_M)
                assert np.allclose(ours[j, :3, :3], R, atol=1e-6)
    finally:
        pybullet.disconnect(c)


def test_surface_points_lie_on_the_inner_face_and_move_rigidly():
    rng = np.random.default_rng(1)
    spec = ArmSpec(name="sp", n_links=5)
    q = rng.uniform(-0.3, 1.0, spec.n_links)
    P = link_surface_points(spec, q, n_along=4, n_height=3)
    T = link_transforms(spec, q)
    # in each link's own frame the points sit at y = +W/2, x in [0, L], |z| <= H/2
    local = np.einsum("nji,nkj->nki", T[:, :3, :3], P - T[:, None, :3, 3])
    assert np.allclose(local[..., 1], spec.link_width / 2)
    assert local[..., 0].min() >= -1e-12 and local[..., 0].max() <= spec.link_length + 1e-12
    assert np.abs(local[..., 2]).max() <= spec.link_height / 2 + 1e-12
    # a base transform moves every point rigidly
    G = _random_T(rng)
    P2 = link_surface_points(spec, q, G, n_along=4, n_height=3)
    assert np.allclose(P2, P @ G[:3, :3].T + G[:3, 3])
    # the face offset pushes the inner face further along +y of each link
    P3 = link_surface_points(spec, q, n_along=4, n_height=3, face_offset=0.001)
    local3 = np.einsum("nji,nkj->nki", T[:, :3, :3], P3 - T[:, None, :3, 3])
    assert np.allclose(local3[..., 1], spec.link_width / 2 + 0.001)
