"""Shared by the GUI tests: waiting for the window by its frames, never by a clock."""


def wait_until(ctx, cond, frames=900):
    """Yield window frames until ``cond()`` holds, at most ``frames`` of them (the window and the
    simulation slow down together on a busy machine, so a frame count is not a wall-clock bound)."""
    for _ in range(frames):
        if cond():
            return True
        ctx.yield_()
    return cond()
