"""The pieces of `jaxrot.comparison`: timing, provenance, and the report of its rows."""
