"""jaxmotion: stochastic 3D human motion prediction in JAX."""

__version__ = "0.1.0"
