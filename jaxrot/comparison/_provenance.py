"""The provenance block every results file carries under ``"machine"``: machine, versions, commit, date."""

import datetime
import importlib.metadata
import os
import platform
import subprocess
from pathlib import Path

import jax


# Version of the provenance block that every results file carries under "machine"; a results file
# with an older one predates the fields the docs' tables read (tests/test_results.py).
RESULTS_SCHEMA = 2


def _git_commit():
    """The checkout's commit (``+dirty`` when the package or the benchmarks differ from it), or None
    outside a git checkout. Docs edited during a run do not mark it."""
    root = Path(__file__).resolve().parents[2]
    try:
        run = lambda *a: subprocess.run(["git", *a], cwd=root, capture_output=True, text=True, timeout=10)  # noqa: E731
        head = run("rev-parse", "--short=12", "HEAD")
        if head.returncode != 0:
            return None
        dirty = run(
            "status", "--porcelain", "--untracked-files=no", "--", "jaxrot", "benchmarks"
        ).stdout.strip()
        return head.stdout.strip() + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return None


def machine_info() -> dict:
    """Where and from what a result was measured: machine, versions, commit, date (UTC), schema."""
    import diffrax as _diffrax

    return {
        "schema": RESULTS_SCHEMA,
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": _git_commit(),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxlib": jax.lib.__version__ if hasattr(jax.lib, "__version__") else None,
        "diffrax": _diffrax.__version__,
        "jaxrot": importlib.metadata.version("jaxrot"),
        "backend": jax.default_backend(),
        "device": str(jax.devices()[0].device_kind),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }
