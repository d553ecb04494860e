"""Regenerate the shipped arm URDFs in urdf/ from explore3d.arm.spec.BUILTIN_ARMS (one command)."""
from pathlib import Path

from explore3d.arm.spec import BUILTIN_ARMS
from explore3d.arm.urdf import write_arm_urdf

if __name__ == "__main__":
    root = Path(__file__).resolve().parents[1] / "urdf"
    for name, spec in BUILTIN_ARMS.items():
        print(write_arm_urdf(spec, root / f"{name}.urdf"))
