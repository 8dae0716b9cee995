"""arapp: augmented reality on printed markers, NURBS overlays, and printing what you see."""

__version__ = "0.1.0"
