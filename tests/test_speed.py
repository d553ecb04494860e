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


def _random_problem(rng, spec, n_contacts):
    """A localisation problem: angles (n,) rad and noisy external torques (n,) N m of
    ``n_contacts`` inner-face contacts."""
    from explore3d.feeling.localise import torques_of_contacts
    n = spec.n_links
    q = rng.uniform(-0.4, 0.4, n) * (rng.random() < 0.5) + rng.uniform(0.0, 0.3, n)
    links = rng.choice(n, size=n_contacts, replace=False)
    cs = [(int(k), (rng.uniform(0.0, spec.link_length), spec.link_width / 2),
           (rng.uniform(-0.3, 0.3), -rng.uniform(0.05, 2.0))) for k in links]
    return q, torques_of_contacts(spec, q, cs) + rng.normal(0.0, 1e-3, n)


def _fit_reference(cols, tau, ridge):
    """The ridge NNLS residual built the plain way: the columns side by side, sqrt(ridge) I below
    them, the torques padded with zeros, scipy.optimize.nnls (inf past the 100 N force cap)."""
    A = np.concatenate(cols, axis=1)
    k = A.shape[1]
    if ridge > 0:
        A = np.vstack([A, np.sqrt(ridge) * np.eye(k)])
        tau = np.concatenate([tau, np.zeros(k)])
    x, rnorm = nnls(A, tau, maxiter=50 * k)
    return float("inf") if x.max() > 100.0 else float(rnorm * rnorm)


def test_fitter_same_numbers_as_plain_nnls_and_bounds_below():
    """_Fitter.rss and _fit_module give the plainly built ridge NNLS residual exactly;
    lower_bounds never exceeds it (NNLS's residual is at least the unconstrained one), also with
    nearly parallel columns."""
    from explore3d.feeling.localise import _Fitter, _fit_module
    rng = np.random.default_rng(5)
    for trial in range(200):
        n, kb, w = 24, 2 * int(rng.integers(0, 4)), int(rng.integers(1, 3))
        base = [rng.normal(size=(n, 2)) for _ in range(kb // 2)]
        extras = rng.normal(size=(30, n, w))
        if trial % 3 == 0:  # nearly parallel to a base column, or to each other
            extras[:, :, 0] = (base[0][:, 0] if base else extras[:, :, -1]) + 1e-7 * rng.normal(size=(30, n))
        tau = rng.normal(size=n) * 0.1
        ridge = float(rng.choice([0.0, 2.5e-9, 1e-4]))
        fit = _Fitter(base, w, tau, ridge=ridge)
        lb = fit.lower_bounds(extras)
        for e, bound in zip(extras, lb):
            r = fit.rss(e)
            assert r == _fit_reference(base + [e], tau, ridge) == _fit_module(base + [e], tau, ridge=ridge)[1]
            assert bound <= r
        assert np.all(lb == -np.inf) if ridge == 0.0 else np.all(np.isfinite(lb))
    assert _Fitter([], 2, np.ones(24), ridge=1e-4).lower_bounds(np.zeros((0, 24, 2))).shape == (0,)


def test_localise_with_no_candidate_on_the_links_allowed():
    """Torques only the proximal joints see, and contacts allowed on the tip alone (as
    contacts.localise_moment's second try asks): no candidate, no contact, no error."""
    from explore3d.feeling.localise import localise, torques_of_contacts
    spec = load_arm("default")
    q = np.full(spec.n_links, 0.05)
    tau = torques_of_contacts(spec, q, [(2, (0.5 * spec.link_length, spec.link_width / 2), (0.0, -1.0))])
    loc = localise(spec, q, tau, links=(spec.n_links - 1,))
    assert loc.contacts == () and loc.rss == loc.rss0


@pytest.mark.parametrize("arm", ["default", "paper"])
def test_localise_skipped_fits_change_nothing(arm, monkeypatch):
    """The fits localise skips by their lower bounds would not have changed its answer: with every
    fit made (no bounds) the contacts, intervals and residuals are the same numbers."""
    from explore3d.feeling import localise as loc
    spec = load_arm(arm)
    rng = np.random.default_rng(8)
    problems = [_random_problem(rng, spec, int(rng.integers(1, 4))) for _ in range(40)]
    fast = [loc.localise(spec, q, tau, position_sigma_m=1e-4 * (i % 2)) for i, (q, tau) in enumerate(problems)]
    monkeypatch.setattr(loc._Fitter, "lower_bounds", lambda self, extras: np.full(len(extras), -np.inf))
    full = [loc.localise(spec, q, tau, position_sigma_m=1e-4 * (i % 2)) for i, (q, tau) in enumerate(problems)]
    for a, b in zip(fast, full):
        assert a.rss == b.rss and np.array_equal(a.predicted, b.predicted)
        assert [(c.link, c.kind) for c in a.contacts] == [(c.link, c.kind) for c in b.contacts]
        for ca, cb in zip(a.contacts, b.contacts):
            assert np.array_equal(ca.point_world, cb.point_world) and np.array_equal(ca.force_world, cb.force_world)
            assert np.array_equal(ca.along_interval_m, cb.along_interval_m, equal_nan=True)


def test_feed_forward_recomputed_only_when_the_reading_changes():
    """The controller's gravity feed-forward is gravity_torques at the reading's angles, the same
    numbers whether it was kept from the step before (unchanged angles) or computed again."""
    from types import SimpleNamespace
    from explore3d.strategy.encircle import ControlConfig, Controller
    spec = load_arm("default")
    T = spatial_wrap_poses([0.0, 0.0, 0.0], 0.07, spec.link_width, 4, 1, 1)[1].T_world_base
    g = np.array([0.0, 0.0, -9.81])
    ctl = Controller(SimpleNamespace(spec=spec, gravity=g), ControlConfig(), T)
    rng = np.random.default_rng(2)
    q1, q2 = rng.uniform(-0.3, 0.3, (2, spec.n_links))
    a = ctl._feed_forward(q1)
    assert np.array_equal(a, -gravity_torques(spec, q1, T, g))
    assert ctl._feed_forward(q1.copy()) is a  # the same angles: kept
    b = ctl._feed_forward(q2)
    assert np.array_equal(b, -gravity_torques(spec, q2, T, g)) and not np.array_equal(a, b)
    with pytest.raises(ValueError):
        a[0] = 1.0  # read only: a caller cannot change what the next step reuses
