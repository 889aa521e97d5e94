"""mkdocs hook: the executed notebooks draw their figures inline, whatever the caller's backend.

ipykernel selects matplotlib's inline backend only when ``MPLBACKEND`` is unset; CI (and many
shells) export ``MPLBACKEND=Agg``, and a kernel started under it would show no plot at all. The
kernels mkdocs-jupyter starts inherit this process's environment.
"""

import os


INLINE = "module://matplotlib_inline.backend_inline"


def on_config(config):
    os.environ["MPLBACKEND"] = INLINE
    return config
