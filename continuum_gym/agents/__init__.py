"""continuum_gym.agents."""
