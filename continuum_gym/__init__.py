"""continuum-gym: Gymnasium environments for continuum surgical robots beside an endoscope."""

__version__ = "0.1.0"

__all__ = ["__version__"]
