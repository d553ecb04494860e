"""Measure the contact bands of the built-in arms' default settings and write them into the
package (``explore3d/data/band-<key>.json``), the factory calibration ``cached_band`` reads.

    python scripts/make_bands.py

Rerun after changing anything the key covers (arm, ControlConfig, SimConfig, SensorConfig, the
calibration protocol or the package version); ``tests/test_robot.py`` fails until then.
"""
import json

from explore3d import load_arm
from explore3d.world.band import FACTORY_SETTINGS, band_cache_key, calibrate_band, factory_band_path
from explore3d.strategy.encircle import ControlConfig
from explore3d.core.io import atomic_write_text
from explore3d.robot.sensing import SensorConfig
from explore3d.core.settings import SimConfig


def main():
    for arm, planar in FACTORY_SETTINGS:
        spec = load_arm(arm)
        key = band_cache_key(spec, ControlConfig(), SimConfig(), SensorConfig(), planar)
        band = calibrate_band(spec, ControlConfig(), SimConfig(), SensorConfig(), planar)
        path = factory_band_path(key)
        atomic_write_text(path, json.dumps(band.to_dict(), indent=1) + "\n")
        print(f"{arm} {'planar' if planar else '3d'}: {path.name} ({band.provenance['wall_s']:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
