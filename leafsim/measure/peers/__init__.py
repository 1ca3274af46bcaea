"""Other engines doing the bench's spring job (``pip install -e ".[peers]"``: warp-lang,
taichi).  Each module imports its engine at import time; :func:`available` lists the ones that
import.  Every peer works in float32 on the bench's own springs, colour order, and exposes
``Peer(q0, ij, rec, colour_start)`` with ``reset()``, ``run(npass)`` and ``positions()``."""

from __future__ import annotations

import importlib

PEERS = {"warp CPU": "leafsim.measure.peers.warp_springs", "taichi CPU": "leafsim.measure.peers.taichi_springs"}


def available() -> dict:
    """name → Peer class of every peer engine that imports here."""
    out = {}
    for name, mod in PEERS.items():
        try:
            out[name] = importlib.import_module(mod).Peer
        except Exception:  # not installed or broken: simply not raced
            continue
    return out
