"""gymnasium-robotics' Fetch tasks as worlds (`fetch:<EnvId>`); see sim.fetch.world."""
