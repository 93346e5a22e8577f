"""NumPy references of the gauss family (clvis/gauss/), module for module."""
