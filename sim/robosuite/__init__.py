"""robosuite's manipulation environments as worlds (`robosuite:<Env>`); see sim.robosuite.world."""
