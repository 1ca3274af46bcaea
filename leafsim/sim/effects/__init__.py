"""Switchable simulation stages, one file each.  Each holds only solver settings and cached
matrices and calls module-level numba kernels with every array passed explicitly.  A disabled
stage is never constructed (costs nothing) and leaves its part of the State untouched.

The effect names come from the one parameter declaration (the ``effects.*`` switches of
:mod:`leafsim.config.params`), so they are listed in one place.
"""

from leafsim.config.params import PARAMS
from leafsim.sim.effects.colour import Colour
from leafsim.sim.effects.dynamics import Dynamics
from leafsim.sim.effects.osmosis import Osmosis
from leafsim.sim.effects.shrink import Shrink

#: every effect a scene can switch, in the order the parameters declare them
EFFECTS = tuple(name.split(".", 1)[1] for name in PARAMS if name.startswith("effects."))

__all__ = ["EFFECTS", "Colour", "Dynamics", "Osmosis", "Shrink"]
