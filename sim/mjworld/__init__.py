"""MuJoCo environments as worlds: a generic layer (MujocoWorld) that a package's environment
enters through a few hooks; sim.fetch is one."""
