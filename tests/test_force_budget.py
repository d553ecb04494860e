"""Contact at a bounded force on a resting object: the budget, the sweeps within it, the press and
the averaged reading's uncertainty (pure functions and configuration)."""
import math

import numpy as np
import pytest

from explore3d.arm.spec import ArmSpec
from explore3d.arm.urdf import load_arm
from explore3d.core.settings import SceneConfig
from explore3d.feeling.contacts import MODEL_TORQUE_SIGMA_NM, torque_sigma_nm
from explore3d.robot.sensing import SensorConfig
from explore3d.strategy.encircle import ControlConfig, force_budget_n, sweep_torque_limits
from explore3d.world.scene import scene_explore_config

DEFAULT = load_arm("default")


def test_the_budget_is_a_fraction_of_the_static_friction():
    assert force_budget_n(0.1, 0.5) == pytest.approx(0.5 * 0.5 * 0.1 * 9.81)
    assert force_budget_n(0.2, 0.5, margin=1.0) == pytest.approx(2 * force_budget_n(0.1, 0.5, margin=1.0))
    for bad in ({"least_mass_kg": 0.0, "friction": 0.5}, {"least_mass_kg": 0.1, "friction": -1.0},
                {"least_mass_kg": 0.1, "friction": 0.5, "margin": 1.5}):
        with pytest.raises(ValueError, match="force_budget_n"):
            force_budget_n(**bad)


@pytest.mark.parametrize("arm", [DEFAULT, ArmSpec(name="small12", n_links=12, link_length=0.025)])
@pytest.mark.parametrize("force", [0.1, 0.245, 1.0])
def test_within_budget_keeps_every_sweep_under_the_force_at_two_links(arm, force):
    cfg = ControlConfig.within_budget(arm, force)
    assert float(sweep_torque_limits(arm, cfg).max()) <= force * 2 * arm.link_length * (1 + 1e-9)
    assert cfg.ramp_time >= ControlConfig.gentle().ramp_time
    # only the ramp changes, and a larger budget never needs a longer one
    assert cfg == ControlConfig(**{**ControlConfig.gentle().__dict__, "ramp_time": cfg.ramp_time})
    assert ControlConfig.within_budget(arm, 2 * force).ramp_time <= cfg.ramp_time


def test_a_budget_below_the_margin_is_refused():
    with pytest.raises(ValueError, match="torque margin"):
        ControlConfig.within_budget(DEFAULT, 0.01)  # 0.4 mN m at two links < the 2 mN m margin


def test_the_table_scene_presses_within_its_budget():
    cfg = scene_explore_config("table")
    budget = force_budget_n(cfg.scene.least_mass_kg, cfg.scene.table_friction)
    assert budget == pytest.approx(0.245, abs=1e-3)
    assert float(sweep_torque_limits(DEFAULT, cfg.control).max()) <= budget * 2 * DEFAULT.link_length * (1 + 1e-9)
    assert cfg.scene.rolling_friction_m > 0 and cfg.scene.spinning_friction_m > 0


def test_press_and_average_settings_are_checked():
    with pytest.raises(ValueError, match="press_while_settling"):
        ControlConfig(press_force_n=0.2, press_while_settling=False)
    with pytest.raises(ValueError, match="press_force_n"):
        ControlConfig(press_force_n=0.0)
    with pytest.raises(ValueError, match="average_steps"):
        ControlConfig(average_steps=-1)
    with pytest.raises(ValueError, match="least_mass_kg"):
        SceneConfig(least_mass_kg=0.0)
    with pytest.raises(ValueError, match="rolling_friction_m"):
        SceneConfig(rolling_friction_m=-1e-3)


def test_the_mean_of_n_readings_has_sigma_over_sqrt_n_down_to_the_models_floor():
    s = SensorConfig()
    one = torque_sigma_nm(s)
    assert one == pytest.approx(math.hypot(1e-3, 1e-3 / math.sqrt(12)))
    assert torque_sigma_nm(s, 4) == pytest.approx(one / 2)
    assert torque_sigma_nm(s, 10_000) == MODEL_TORQUE_SIGMA_NM
    # the noise of a mean of dithered, quantised readings does fall as 1/sqrt(n) (the claim above)
    rng = np.random.default_rng(0)
    true = 3.3e-4
    reads = np.round((true + rng.normal(0, 1e-3, (20000, 16))) / 1e-3) * 1e-3
    assert np.std(reads.mean(axis=1)) == pytest.approx(one / 4, rel=0.05)
