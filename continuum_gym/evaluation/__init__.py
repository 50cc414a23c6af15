"""continuum_gym.evaluation."""
