"""Shared fixtures.  ``xdisplay`` starts a private Xvfb server for GUI tests only (when no
DISPLAY is set) and stops it at the end of the session; other tests never need it.
``tiny`` is the bench's small leaf (a maple-like outline at a coarse mesh), built once.

The tests mirror the package's folders (``tests/sim/`` tests ``leafsim/sim/``); shared test
code lives in ``tests/helpers/`` (importable as ``helpers.*``: ``tests`` is on the path).
Markers: ``gui`` (the real window under Xvfb), ``slow`` (``-m "not slow"`` skips them)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import threading
import time

import pytest
from hypothesis import HealthCheck, settings

# leafsim first: it points numba's cache at a folder keyed to the kernel sources, which only
# works before anything imports numba (the reference kernels of tests/helpers/pbd_reference.py call
# leafsim's, so their cached code must not outlive a change there either)
import leafsim  # noqa: F401

# property-based tests (tests/test_properties.py): a quick, reproducible profile by default;
# HYPOTHESIS_PROFILE=nightly runs 30x the examples with fresh randomness (a longer, nightly run)
settings.register_profile("quick", max_examples=40, deadline=None, derandomize=True, database=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("nightly", max_examples=1200, deadline=None, database=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "quick"))

# Ctrl-C as an interactive Python has it, however the suite was started: a suite launched in the
# background of a script inherits SIGINT ignored (POSIX), its workers and their children too,
# and the tests that interrupt a run or a scene with SIGINT then waited out their patience
if threading.current_thread() is threading.main_thread():
    signal.signal(signal.SIGINT, signal.default_int_handler)


def _free_display() -> int:
    for n in range(99, 300):
        if not os.path.exists(f"/tmp/.X{n}-lock") and not os.path.exists(f"/tmp/.X11-unix/X{n}"):
            return n
    raise RuntimeError("no free X display number in :99..:299")


@pytest.fixture(scope="session")
def xdisplay():
    """The X display GUI tests run on (``DISPLAY`` value); starts Xvfb 1280x800x24 if needed."""
    if os.environ.get("DISPLAY"):
        yield os.environ["DISPLAY"]
        return
    if shutil.which("Xvfb") is None:
        pytest.fail("GUI tests need an X display: no DISPLAY and no Xvfb (scripts/setup.sh installs xvfb)")
    proc = None
    for _ in range(5):
        n = _free_display()
        proc = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.time() + 120  # Xvfb's socket appears in milliseconds; a bound against a hang
        while time.time() < deadline and proc.poll() is None:
            if os.path.exists(f"/tmp/.X11-unix/X{n}"):
                break
            time.sleep(0.05)
        if proc.poll() is None and os.path.exists(f"/tmp/.X11-unix/X{n}"):
            break
        proc.kill()
        proc.wait()
        proc = None
    if proc is None:
        pytest.fail("GUI tests need an X display: Xvfb did not start")
    display = f":{n}"
    # wait until the server answers (xdpyinfo-free: a client connection via xdotool if present)
    if shutil.which("xdotool"):
        for _ in range(100):
            r = subprocess.run(["xdotool", "getdisplaygeometry"], env={**os.environ, "DISPLAY": display},
                               capture_output=True)
            if r.returncode == 0:
                break
            time.sleep(0.05)
    os.environ["DISPLAY"] = display
    try:
        yield display
    finally:
        os.environ.pop("DISPLAY", None)
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.fixture(scope="session")
def tiny():
    """The bench's tiny leaf (a coarse maple-like blade), built once per test session."""
    from leafsim.measure.models import build_bench_model

    return build_bench_model("tiny")


def pytest_collection_modifyitems(items):
    """Every test in tests/gui/ drives the real window: marked ``gui``."""
    for item in items:
        if "/tests/gui/" in str(item.path).replace("\\", "/") and item.path.name != "test_fonts.py":
            item.add_marker(pytest.mark.gui)
