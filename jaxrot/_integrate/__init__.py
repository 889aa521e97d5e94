"""Stepping many bodies through time.

`rollout` and its chunked, cache-blocked, sharded and NaN-checked variants, and driven bodies.
"""
