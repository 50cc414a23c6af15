"""A researcher's package of continuum-gym plug-ins (the worked example of docs/tutorials/variant.md)."""
