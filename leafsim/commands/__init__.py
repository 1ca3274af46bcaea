"""One module per group of ``leafsim`` commands: each ``cmd_*`` function takes the parsed
arguments of :mod:`leafsim.cli` and calls the stages that do the work.  Nothing below this
package imports it.  This file holds only the constants the parser shows in its help, so
parsing loads none of the command modules."""

#: the checkpoint file of ``leafsim run`` inside --out, and how often it is written by default
CHECKPOINT = "checkpoint.npz"
CHECKPOINT_EVERY = 100
