"""leafsim — procedural leaves and a physically based simulation of how they age.

Importing the package does no work: data folders are found on demand
(:mod:`leafsim.base.resources`) and numba's kernel cache is set up by the first kernel module
imported (:mod:`leafsim.base.cache`).  ``docs/architecture.md`` shows the stages and what each
may import.
"""

__version__ = "0.1.0"
