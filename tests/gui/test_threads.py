"""The render threads llvmpipe may use beside the simulation worker (leafsim.gui.threads)."""

from leafsim.gui.threads import render_threads


def test_render_threads_leave_the_worker_a_core():
    # 2 render threads against 1 on the 2-core machine: 41.7 / 34.9 fps and 0.116 / 0.111
    # simulated s per s, against 32.8 / 30.8 fps and 0.171 / 0.152 (the module docstring)
    assert [render_threads(n) for n in (1, 2, 3, 4, 5, 8, 64)] == ["1", "1", "2", "3", "4", "4", "4"]
