"""PyTorch re-implementations of jaxmotion's networks, for parity tests and speed benchmarks.

Written for this benchmark from the papers and from jaxmotion's own modules (not copied from the
papers' released code). Every module has exactly the layers and parameter counts of its jaxmotion
twin, and `convert.py` loads jaxmotion parameters into it, so the two frameworks run the same
computation on the same weights.
"""
