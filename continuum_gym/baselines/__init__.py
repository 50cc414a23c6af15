"""continuum_gym.baselines."""
