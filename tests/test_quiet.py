"""explore3d.quiet_c_output: C-level output on fds 1 and 2 vanishes, Python's own output stays."""
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _python(code):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)


def test_c_level_writes_vanish_and_python_output_stays():
    r = _python(
        "import os, sys\n"
        "from explore3d import quiet_c_output\n"
        "print('before', flush=True)\n"
        "with quiet_c_output():\n"
        "    os.write(1, b'C-level stdout\\n'); os.write(2, b'C-level stderr\\n')\n"
        "    print('python stdout'); print('python stderr', file=sys.stderr)\n"
        "    with quiet_c_output():  # nested\n"
        "        os.write(1, b'inner C\\n'); print('inner python')\n"
        "os.write(1, b'after C\\n')\n")
    assert r.returncode == 0, r.stderr
    assert r.stdout == "before\npython stdout\ninner python\nafter C\n"
    assert r.stderr == "python stderr\n"


def test_pybullet_connect_and_solver_switch_are_silent():
    """What sim.ArmSimulation does on construction, inside the helper: nothing reaches either stream
    (without it: the build time on stderr, the solver banners on stdout)."""
    code = ("import pybullet as p\n"
            "c = p.connect(p.DIRECT)\n"
            "p.setPhysicsEngineParameter(constraintSolverType=p.CONSTRAINT_SOLVER_LCP_DANTZIG, physicsClientId=c)\n"
            "p.disconnect(c)\n")
    loud = _python(code)
    assert "switched solver" in loud.stdout and "pybullet build time" in loud.stderr  # the banners exist
    quiet = _python("from explore3d import quiet_c_output\nwith quiet_c_output():\n"
                    + "".join("    " + ln + "\n" for ln in code.splitlines()) + "print('ok')\n")
    assert quiet.returncode == 0, quiet.stderr
    assert quiet.stdout == "ok\n" and quiet.stderr == ""
