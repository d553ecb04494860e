"""Contact localisation from joint torques (explore3d.feeling.localise) on synthetic contacts."""
import numpy as np
import pytest

from explore3d.arm.spec import DEFAULT_ARM
from explore3d.arm.kinematics import link_transforms, point_jacobian
from explore3d.feeling.localise import external_torques, localise

SPEC = DEFAULT_ARM


def _config(seed):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.05, 0.35, SPEC.n_links)


def _base(seed):
    rng = np.random.default_rng(seed + 100)
    a = rng.uniform(0, 2 * np.pi)
    T = np.eye(4)
    T[:3, :3] = [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
    T[:3, 3] = rng.uniform(-0.2, 0.2, 3)
    return T


def _tau(q, T, contacts):
    """External joint torques of forces (link, point_link (3,), force_link (3,)) via point_jacobian."""
    Tl = link_transforms(SPEC, q, T)
    tau = np.zeros(SPEC.n_links)
    for link, p, f in contacts:
        J = point_jacobian(SPEC, q, link, p, T)
        tau += J.T @ (Tl[link, :3, :3] @ np.asarray(f, float))
    return tau


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_single_face_contact_exact(seed):
    q, T = _config(seed), _base(seed)
    W = SPEC.link_width
    link, x = 7 + seed * 3, 0.0123
    p = np.array([x, W / 2, 0.003])  # height unobservable: located at mid-height
    tau = _tau(q, T, [(link, p, [0.0, -0.8, 0.0])])
    loc = localise(SPEC, q, tau, T, sigma_nm=1e-6)
    assert len(loc.contacts) == 1
    c = loc.contacts[0]
    assert c.link == link and c.kind == "inner"
    assert np.allclose(c.point_link, [x, W / 2, 0.0], atol=1e-6)
    Tl = link_transforms(SPEC, q, T)[link]
    assert np.allclose(c.point_world, Tl[:3, :3] @ [x, W / 2, 0.0] + Tl[:3, 3], atol=1e-6)
    assert c.force_n == pytest.approx(0.8, rel=1e-6)
    assert np.allclose(c.normal_world, -Tl[:3, 1], atol=1e-6)
    assert c.segment_world.shape == (2, 3) and c.height_interval == (-SPEC.link_height / 2, SPEC.link_height / 2)


def test_two_contacts_on_different_links():
    q, T = _config(5), _base(5)
    W = SPEC.link_width
    truth = [(4, np.array([0.006, W / 2, 0.0]), [0.0, -1.2, 0.0]), (15, np.array([0.015, W / 2, 0.0]), [0.0, -0.5, 0.0])]
    tau = _tau(q, T, truth)
    loc = localise(SPEC, q, tau, T, sigma_nm=1e-6)
    assert [c.link for c in loc.contacts] == [4, 15]
    for c, (_, p, f) in zip(loc.contacts, truth):
        assert np.allclose(c.point_link, p, atol=1e-6)
        assert c.force_n == pytest.approx(np.linalg.norm(f), rel=1e-6)


def test_zero_torques_no_contact():
    loc = localise(SPEC, _config(3), np.zeros(SPEC.n_links), None, sigma_nm=1e-3)
    assert loc.contacts == ()
    rng = np.random.default_rng(0)  # pure noise: no contact either
    loc = localise(SPEC, _config(3), rng.normal(0, 1e-3, SPEC.n_links), None, sigma_nm=1e-3)
    assert loc.contacts == ()


def test_corner_contact_oblique_force():
    q, T = _config(7), _base(7)
    L, W = SPEC.link_length, SPEC.link_width
    link = 11
    p = np.array([L, W / 2, 0.0])  # distal inner corner
    f = np.array([-0.3, -0.6, 0.0])  # inside the cone of the distal and inner normals
    tau = _tau(q, T, [(link, p, f)])
    loc = localise(SPEC, q, tau, T, sigma_nm=1e-6)
    assert len(loc.contacts) == 1
    c = loc.contacts[0]
    assert c.link == link and c.kind == "corner_di"
    assert np.allclose(c.point_link, p, atol=1e-6)
    Tl = link_transforms(SPEC, q, T)[link]
    assert np.allclose(c.force_world, Tl[:3, :3] @ f, atol=1e-6)


def test_external_torques_cancels_gravity():
    from explore3d.arm.kinematics import gravity_torques

    q, T = _config(1), _base(1)
    g = np.array([0.0, 0.0, -9.81])
    T2 = T.copy()
    T2[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # plane vertical
    tau_motor = -gravity_torques(SPEC, q, T2, g)
    assert np.allclose(external_torques(SPEC, q, tau_motor, T2, g), 0.0)


def test_uncertainty_scales_with_noise_over_force():
    q = _config(2)
    W = SPEC.link_width
    tau = _tau(q, None, [(9, [0.01, W / 2, 0.0], [0.0, -1.0, 0.0])])
    a = localise(SPEC, q, tau, None, sigma_nm=1e-4).contacts[0].sigma_along_m
    b = localise(SPEC, q, 0.1 * tau, None, sigma_nm=1e-4).contacts[0].sigma_along_m
    assert 0 < a < 1e-4 and b == pytest.approx(10 * a, rel=1e-6)


def test_interval_contains_truth_and_is_tight_when_exact():
    q = _config(4)
    W = SPEC.link_width
    tau = _tau(q, None, [(12, [0.007, W / 2, 0.0], [0.0, -2.0, 0.0])])
    c = localise(SPEC, q, tau, None, sigma_nm=1e-4).contacts[0]
    lo, hi = c.along_interval_m
    assert lo <= 0.007 <= hi and hi - lo <= 1.5e-3


def test_tip_distal_face():
    q = _config(6)
    n = SPEC.n_links
    tau = _tau(q, None, [(n - 1, [SPEC.link_length, 0.001, 0.0], [-0.5, 0.0, 0.0])])
    c = localise(SPEC, q, tau, None, sigma_nm=1e-7).contacts[0]
    assert c.link == n - 1 and c.kind == "distal"
    assert np.allclose(c.point_link, [SPEC.link_length, 0.001, 0.0], atol=1e-6)


def test_flat_contact_is_its_centre_of_pressure():
    """A link face lying along the object: a distributed normal load is one contact at its centre of pressure."""
    q, T = _config(8), _base(8)
    W = SPEC.link_width
    load = [(10, [x, W / 2, 0.0], [0.0, -w, 0.0]) for x, w in ((0.004, 1.0), (0.010, 2.0), (0.018, 1.0))]
    loc = localise(SPEC, q, _tau(q, T, load), T, sigma_nm=1e-6)
    assert len(loc.contacts) == 1
    c = loc.contacts[0]
    assert c.link == 10 and c.kind == "inner"
    assert np.allclose(c.point_link, [0.0105, W / 2, 0.0], atol=1e-6)  # (0.004 + 0.020 + 0.018) / 4
    assert c.force_n == pytest.approx(4.0, rel=1e-6)
