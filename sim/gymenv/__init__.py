"""A gymnasium environment with image observations and a saveable state, as a world
(sim.gymenv.world): the environment id, a state getter and setter, a table of concept edits."""

from sim.gymenv.world import ConceptEdit, GymWorld

__all__ = ["ConceptEdit", "GymWorld"]
