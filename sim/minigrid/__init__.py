"""Any registered MiniGrid environment as a world: `minigrid:<EnvId>[:tile=N][:view=partial]`.

The files have the roles every world's folder has: concepts.py (the concept space, read from
the environment's grids), state.py (a Scene held in, and read back from, the environment's own
objects), world.py (the World: rendering and dynamics by MiniGrid itself), tasks.py (training
layouts and shifts made from the concept space), expert.py (a breadth-first search over the
environment's own step).
"""
