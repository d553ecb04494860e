"""The external-torque detector (issue 40): the residual of the arm's model against the torques its
servos report is J^T F for a known push (in a PyBullet world, exact sensing), the vectorised
inverse dynamics is the loop form's, and the detector's settings and bands are checked."""
import numpy as np
import pybullet
import pytest

from explore3d.arm.kinematics import link_transforms, point_jacobian
from explore3d.arm.spec import ArmSpec
from explore3d.core.settings import SimConfig
from explore3d.feeling.detect import ContactBand, ExternalTorque, SweepDetector, inverse_dynamics_planar
from explore3d.feeling.localise import inverse_dynamics
from explore3d.robot.sensing import SensorConfig
from explore3d.strategy.encircle import ControlConfig, Controller
from explore3d.world.band import gravity_bounding_bases
from explore3d.world.sim import ArmSimulation

ARM = ArmSpec(name="small8", n_links=8, link_length=0.025)


def test_vectorised_inverse_dynamics_is_the_newton_euler_loop():
    rng = np.random.default_rng(3)
    for _ in range(20):
        q, dq, ddq = rng.normal(size=(3, ARM.n_links))
        np.testing.assert_allclose(inverse_dynamics_planar(ARM, q, dq, ddq), inverse_dynamics(ARM, q, dq, ddq),
                                   rtol=1e-12, atol=1e-15)


def test_at_rest_the_residual_is_minus_motor_and_gravity_torques():
    rng = np.random.default_rng(4)
    q, tau = rng.normal(size=(2, ARM.n_links))
    T = gravity_bounding_bases()[1]
    g = np.array([0.0, 0.0, -9.81])
    ext = ExternalTorque(ARM, T, g)(q, np.zeros(ARM.n_links), tau)
    from explore3d.feeling.localise import external_torques
    np.testing.assert_allclose(ext, external_torques(ARM, q, tau, T, g), rtol=0, atol=1e-15)


@pytest.mark.parametrize("base", [0, 1])  # arm's plane horizontal; vertical (gravity in the plane)
@pytest.mark.parametrize("link", [0, 3, 7])
def test_a_known_push_on_link_k_reads_as_J_transpose_F_on_joints_0_to_k_and_nothing_beyond(link, base):
    """A force applied at a known point of link k while the arm holds a bent pose: after the arm
    comes to rest, the residual on joints 0..k is J^T F within 1 uN m and below that on the joints
    beyond (exact sensing and an exact model: measured agreement 3e-9 N m for a 0.5 N push)."""
    q_hold = np.array([0.3, -0.2, 0.25, 0.1, -0.3, 0.2, 0.15, -0.1])
    T = gravity_bounding_bases()[base]
    p_local = np.array([0.6 * ARM.link_length, ARM.link_width / 2, 0.0])  # on the inner face
    with ArmSimulation(ARM, config=SimConfig()) as world:
        robot = world.robot(SensorConfig.ideal())
        ctl = Controller(robot, ControlConfig(), T)
        ctl.start(q_hold)
        Tl = link_transforms(ARM, q_hold, T)[link]
        F = -0.5 * Tl[:3, 1]  # 0.5 N into the inner face, world frame
        p_world = Tl[:3, :3] @ p_local + Tl[:3, 3]

        def push(w):
            # the link's actual pose (the evaluation's side: this is the test's known force)
            pos, orn = w.client.getLinkState(w.arm, link)[4:6]
            R = np.array(pybullet.getMatrixFromQuaternion(orn)).reshape(3, 3)
            w.client.applyExternalForce(w.arm, link, (R @ -np.array([0.0, 0.5, 0.0])).tolist(),
                                        (R @ p_local + np.array(pos)).tolist(), pybullet.WORLD_FRAME)

        push(world)
        world.step_observer = push
        for _ in range(240):
            ctl.send(q_hold)
        r = ctl.reading
        ext = ExternalTorque(ARM, T, robot.gravity)(r.q, r.dq, r.tau)
    J = point_jacobian(ARM, r.q, link, p_local, T)
    expect = J.T @ F
    np.testing.assert_allclose(ext[: link + 1], expect[: link + 1], atol=1e-6)
    assert np.abs(ext[link + 1:]).max(initial=0.0) < 1e-6
    assert np.abs(expect[: link + 1]).max() > 1e-3  # the push is well above the tolerance


def test_the_torque_channel_fires_on_any_joint_and_only_with_a_torque_band():
    n = ARM.n_links
    band = ContactBand(swept=np.full(n, 1.0), other=np.full(n, 1.0), torque=np.full(n, 0.01))
    det = SweepDetector(5, np.zeros(n), np.zeros(n), ext0=np.zeros(n))
    ext = np.zeros(n)
    ext[1] = 0.05  # a held joint, far from the swept one
    e = det.update_torque(ext)
    assert e[1] == pytest.approx(0.025)  # the two-step mean
    e = det.update_torque(ext)
    assert SweepDetector.exceeds(band, 5, 0.0, np.zeros(n), e)
    assert not SweepDetector.exceeds(band, 5, 0.0, np.zeros(n))  # no torque reading: the stall rule
    stall = ContactBand(swept=band.swept, other=band.other)
    assert not SweepDetector.exceeds(stall, 5, 0.0, np.zeros(n), e)  # no torque band: the stall rule
    assert ContactBand.from_dict(band.to_dict()).torque.tolist() == band.torque.tolist()
    assert ContactBand.from_dict(stall.to_dict()).torque is None


def test_a_push_through_a_held_link_is_told_from_a_touch_of_the_carried_links():
    """J^T F of a 0.1 N push on held link 2 (its joints 0..2 loaded by an earlier contact) is zero
    on joints 3..7, so it leaves only the loaded joints' bands: a push through the held chain; the
    same push on carried link 5 while joint 4 sweeps reaches joints 3..5 too: a new touch."""
    n = ARM.n_links
    q = np.array([0.3, 0.4, 0.35, 0.2, 0.1, 0.3, 0.2, 0.1])
    p_local = np.array([0.5 * ARM.link_length, ARM.link_width / 2, 0.0])
    band = ContactBand(swept=np.full(n, 1.0), other=np.full(n, 1.0), torque=np.full(n, 1e-4),
                       torque_loaded=np.full(n, 1e-3))
    zero = np.zeros(n)
    for link, held in ((2, True), (5, False)):
        Tl = link_transforms(ARM, q)[link]
        ext = point_jacobian(ARM, q, link, p_local).T @ (-0.1 * Tl[:3, 1])
        assert np.abs(ext[: link + 1]).min() > 1e-3 and not ext[link + 1:].any()  # J^T F: joints 0..link only
        assert SweepDetector.exceeds(band, 4, 0.0, zero, ext, loaded=2)
        assert SweepDetector.only_loaded(band, 4, 0.0, zero, ext, loaded=2) is held
        assert not SweepDetector.only_loaded(band, 4, 0.0, zero, ext, loaded=-1)  # nothing held: a touch
        assert not SweepDetector.only_loaded(band, 4, 2.0, zero, ext, loaded=2)  # the swept joint stalls: a touch
        assert not SweepDetector.only_loaded(band, 4, 0.0, zero, None, loaded=2)  # no torque reading


def test_detector_settings_are_checked():
    with pytest.raises(ValueError, match="held_load_action must be"):
        ControlConfig(held_load_action="push")
    with pytest.raises(ValueError, match="detector must be one of"):
        ControlConfig(detector="skin")
    with pytest.raises(ValueError, match="torque must be finite"):
        ContactBand(swept=np.ones(3), other=np.ones(3), torque=np.ones(2))
