"""Data shipped inside the package (read with importlib.resources, so it works from a wheel)."""
