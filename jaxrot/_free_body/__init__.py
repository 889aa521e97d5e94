"""The torque-free body.

The free rotor of the splittings (DMV) and the closed-form solutions (Jacobi elliptic functions).
"""
