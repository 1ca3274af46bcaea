"""The command line's contract for a failed command, shared by the command tests."""

from __future__ import annotations

import json


def stdout_of_a_failure(code: int, out: str, err: str) -> None:
    """A failed command prints nothing on stdout, or with ``--json`` exactly one JSON object:
    the error line's message and the exit status."""
    if out == "":
        return
    assert out.endswith("\n") and out.count("\n") == 1, repr(out)
    doc = json.loads(out)
    assert set(doc) == {"command", "error", "exit"} and doc["exit"] == code, doc
    assert err.startswith("leafsim: ") and doc["error"] in err, (doc, err)
