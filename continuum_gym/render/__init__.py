"""continuum_gym.render."""
