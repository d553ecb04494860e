"""The one rule for the optional open3d in the tests.

A test that needs open3d itself (its backend, or open3d as an independent reference) carries
``@pytest.mark.needs_open3d`` and is skipped, with the import error as the reason, when open3d
cannot be imported (it is an optional dependency: ``pip install -e ".[open3d]"``; its Linux wheels
also need the system library libusb-1.0).  Code paths with a scipy/trimesh fallback are tested
without the marker, so they run (on the fallback) everywhere.

Check the rule with ``EXPLORE3D_TEST_HIDE_OPEN3D=1 python -m pytest ...``: open3d is then made
unimportable for the whole session, as on a machine without it.
"""
import os
import sys

import pytest

if os.environ.get("EXPLORE3D_TEST_HIDE_OPEN3D"):
    sys.modules["open3d"] = None  # every `import open3d` now raises ImportError

# The contact bands are measured once per setting and cached on disk (explore3d.world.band.cached_band).
# The tests measure their own in a fresh folder, so no cache from earlier code or runs leaks in
# (worker processes and subprocesses inherit the variable).  One folder for the whole session: the
# xdist workers inherit the controller's, so a band one worker measured (or is measuring: the
# cache's lock) is not measured again by the other.
_inherited = os.environ.get("EXPLORE3D_TEST_CACHE_SET")  # the folder this session's controller made
if not os.environ.get("EXPLORE3D_TEST_KEEP_CACHE") and not (
        _inherited and _inherited == os.environ.get("EXPLORE3D_CACHE_DIR") and os.path.isdir(_inherited)):
    import tempfile

    os.environ["EXPLORE3D_CACHE_DIR"] = os.environ["EXPLORE3D_TEST_CACHE_SET"] = tempfile.mkdtemp(
        prefix="explore3d-test-cache-")


def open3d_import_error() -> str | None:
    """None if open3d imports, else the first line of the reason it does not."""
    try:
        import open3d  # noqa: F401
    except (ImportError, OSError) as exc:
        return (str(exc).splitlines() or [type(exc).__name__])[0]
    return None


def pytest_configure(config):
    config.addinivalue_line("markers", "needs_open3d: the test uses open3d; skipped (with the reason) without it")


def pytest_runtest_setup(item):
    if item.get_closest_marker("needs_open3d") is not None:
        err = open3d_import_error()
        if err is not None:
            pytest.skip(f"open3d cannot be imported ({err}); pip install -e '.[open3d]' (and apt-get install "
                        "libusb-1.0-0) to run this test")
