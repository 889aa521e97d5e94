"""jaxrot inside diffrax.

The rigid-body term, the schemes as diffrax solvers, their interpolation, and the reference solver.
"""
