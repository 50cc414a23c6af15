"""continuum_gym.envs."""
