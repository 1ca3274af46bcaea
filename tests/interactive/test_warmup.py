"""The first run of a leafsim version compiles its kernels up front and says so
(leafsim.interactive.warmup): the CLI prints a line before and one after, the GUI's first build
shows it as a stage with a count; once the cache is warm nothing is said and nothing waits."""

from __future__ import annotations

import io
import os
import subprocess
import sys

import numpy as np
import pytest
from numba import njit

from leafsim.interactive import builder, warmup


@pytest.fixture
def cold(tmp_path, monkeypatch):
    """A marker in a fresh folder: the kernels count as not compiled yet."""
    marker = tmp_path / "leafsim-warm-test"
    monkeypatch.setattr(warmup, "_marker", lambda: marker)
    monkeypatch.setattr(warmup, "_done_here", False)
    return marker


def _compile_two():
    """An exercise that really compiles (two fresh, uncached functions, one calling the other)."""
    @njit
    def inner(x):
        return x * 2.0

    @njit
    def outer(a):
        s = 0.0
        for v in a:
            s += inner(v)
        return s

    assert outer(np.arange(3.0)) == 6.0


def test_the_marker_names_the_kernels_folder(monkeypatch, tmp_path):
    """numba files its cache under the kernel sources' own folder, so a checkout at another path
    compiles anew: its marker must differ too (a second clone was told nothing while it compiled
    for 13 s, the first clone's marker saying warm)."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(warmup, "configure_numba_cache", lambda: str(tmp_path))
    marks = []
    for where in (warmup.__file__, str(tmp_path / "elsewhere" / "leafsim" / "interactive" / "warmup.py")):
        monkeypatch.setattr(warmup, "__file__", where)
        monkeypatch.setattr(warmup, "_marker_path", [])
        marks.append(warmup._marker())
    assert marks[0] is not None and marks[0].parent == tmp_path and marks[0] != marks[1]


def test_warm_up_counts_compiles_and_marks_the_cache(cold):
    seen = []
    n, seconds, kept = warmup.warm_up(lambda k, s: seen.append((k, s)), exercise=_compile_two)
    assert n == 2 and [k for k, _ in seen] == [1, 2] and seconds >= 0.0 and kept
    assert cold.is_file() and warmup.is_warm()
    assert warmup.warm_up(exercise=_compile_two) is None  # warm: at once, nothing run


def test_cli_says_what_it_compiles_once(cold, monkeypatch):
    monkeypatch.setattr(warmup, "_exercise", _compile_two)
    out = io.StringIO()
    warmup.warm_up_cli(out)
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("leafsim: compiling the simulation kernels") and "once" in lines[0]
    assert lines[-1].startswith("leafsim: compiled 2 kernels in ") and lines[-1].endswith("(cached for the next runs)")
    again = io.StringIO()
    warmup.warm_up_cli(again)
    assert again.getvalue() == ""


def test_gui_build_shows_the_compile_as_its_first_stage(cold, monkeypatch):
    monkeypatch.setattr(warmup, "_exercise", _compile_two)
    reports = []
    builder._warm_up(lambda p, t: reports.append((p, t)))
    assert reports[0] == (0.0, f"{builder.WARM_TEXT}: 0 done, 0 s")
    assert reports[-1][1].startswith(f"{builder.WARM_TEXT}: 2 done, ")
    reports.clear()
    builder._warm_up(lambda p, t: reports.append((p, t)))  # warm: no stage at all
    assert reports == []


def test_a_newer_build_cancels_after_the_compile(cold, monkeypatch):
    marker = cold
    monkeypatch.setattr(warmup, "_exercise", _compile_two)

    def report(p, t):
        raise builder.Cancelled()

    with pytest.raises(builder.Cancelled):
        builder._warm_up(report)
    assert marker.is_file()  # the compile ran to its end (it is needed anyway)


def test_one_warm_up_at_a_time(cold, monkeypatch):
    """A second build asking while the first compiles waits, then finds the kernels compiled."""
    import threading

    runs = []

    def slow_exercise():
        runs.append(1)
        _compile_two()

    monkeypatch.setattr(warmup, "_exercise", slow_exercise)
    results = []
    threads = [threading.Thread(target=lambda: results.append(warmup.warm_up())) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert len(runs) == 1 and sorted(r is None for r in results) == [False, True, True]


def test_a_failed_or_uncached_warm_up_is_said_and_the_command_goes_on(cold, monkeypatch):
    def broken():
        raise RuntimeError("no\nleaf")

    monkeypatch.setattr(warmup, "_exercise", broken)
    out = io.StringIO()
    warmup.warm_up_cli(out)  # no exception
    last = out.getvalue().splitlines()[-1]
    assert last.startswith("leafsim: the kernel warm-up failed (RuntimeError: no leaf)") and not cold.exists()
    reports = []
    builder._warm_up(lambda p, t: reports.append(t))  # the GUI's build goes on too
    assert reports and not cold.exists()
    # no writable cache folder: compiled once in this process, and said so truthfully
    monkeypatch.setattr(warmup, "_marker", lambda: None)
    monkeypatch.setattr(warmup, "_exercise", _compile_two)
    out = io.StringIO()
    warmup.warm_up_cli(out)
    assert "no writable cache folder" in out.getvalue().splitlines()[-1]
    again = io.StringIO()
    warmup.warm_up_cli(again)  # this process has compiled them: quiet
    assert again.getvalue() == ""


@pytest.mark.slow
def test_a_cold_command_announces_the_compile_and_a_warm_one_does_not(tmp_path):
    """End to end in a fresh kernel cache: the first command compiles (announced on stderr, its
    --json stdout still one object), the second one loads and says nothing."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    cmd = [sys.executable, "-m", "leafsim", "run", "--species", "maple", "--quality", "draft", "--frames", "1", "--json"]
    first = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
    assert first.returncode == 0, first.stderr
    err = first.stderr.splitlines()
    assert err[0].startswith("leafsim: compiling the simulation kernels")
    assert err[-1].startswith("leafsim: compiled ") and int(err[-1].split()[2]) > 50
    assert first.stdout.lstrip().startswith("{") and first.stdout.rstrip().endswith("}")
    second = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
    assert second.returncode == 0 and second.stderr == ""
