"""What `regenerate.py` knows about a results file beyond its numbers: the code it measured, and
whether the machine was quiet while it was measured.

- **Sources.** Each job names the repository paths (files or folders) its numbers depend on: the
  benchmark script and the package code it measures. When the job runs, a fingerprint of every file
  under them goes into the results file's ``machine["sources"]``; a result is *stale* once one of
  those files' fingerprint differs from the one it recorded (or, for a file written before sources
  were recorded, from the file at the commit it names). A Python file's fingerprint is that of its
  syntax tree without docstrings, so a comment, a docstring or a reformatting does not make a
  result stale, and any change to what the code does does; other files are hashed as they are.
- **Load.** On 2 cores a ratio timed beside another computation is not the ratio. `LoadWatch` takes
  the machine's busy CPU time (``/proc/stat``) and the job's own (its process tree, from
  ``getrusage(RUSAGE_CHILDREN)``) over the run: what the rest of the machine used, in cores on average,
  is the load the job's timings could not see. It also records the load average before and after.
"""

import ast
import functools
import hashlib
import json
import os
import resource
import subprocess
import time
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]

# Cores the rest of the machine may use, on average over a timed job, for its figures to count as
# measured on quiet cores: a tenth of this project's 2-core machine (background daemons, the shell and
# the harness itself use a few hundredths; one more compiling process uses about one).
QUIET_OTHER_CORES = 0.2


def _git(*args, check=False):
    run = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=60)
    if check and run.returncode != 0:
        raise RuntimeError(f"git {' '.join(args)}: {run.stderr.strip()}")
    return run


def source_files(sources):
    """The files (repository-relative, sorted) under ``sources``, tracked or not, that exist now."""
    if not sources:
        return []
    listed = _git("ls-files", "--cached", "--others", "--exclude-standard", "--", *sources, check=True)
    return sorted({f for f in listed.stdout.splitlines() if (ROOT / f).is_file()})


def fingerprint(path, text):
    """A short hash of what the file ``path`` with contents ``text`` does (see the module docstring)."""
    if path.endswith(".py"):
        try:
            tree = ast.parse(text)
        except SyntaxError:
            pass
        else:
            for node in ast.walk(tree):
                body = getattr(node, "body", None)
                if (
                    isinstance(body, list)
                    and body
                    and isinstance(body[0], ast.Expr)
                    and isinstance(body[0].value, ast.Constant)
                    and isinstance(body[0].value.value, str)
                ):
                    node.body = body[1:] or [ast.Pass()]
            text = ast.dump(tree)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def source_hashes(sources):
    """``{path: fingerprint}`` of the files under ``sources`` as they are in the work tree now."""
    return {f: fingerprint(f, (ROOT / f).read_text(errors="replace")) for f in source_files(sources)}


@functools.cache
def _fingerprint_at(commit, path):
    """The fingerprint of ``path`` at ``commit``, or None where it did not exist."""
    shown = _git("show", f"{commit}:{path}")
    return fingerprint(path, shown.stdout) if shown.returncode == 0 else None


def stale_sources(machine, sources):
    """The reasons a result with provenance block ``machine`` no longer measures the code under
    ``sources``: changed, added or removed files, or why that cannot be told. Empty when current."""
    recorded = machine.get("sources")
    if recorded is not None:
        now = source_hashes(sources)
        changed = sorted(f for f in set(now) | set(recorded) if now.get(f) != recorded.get(f))
        where = "since"
    else:
        commit = str(machine.get("commit") or "")
        if not commit:
            return ["no commit recorded"]
        if commit.endswith("+dirty"):
            return [f"measured from uncommitted code at {commit} and no source fingerprints recorded"]
        if _git("cat-file", "-e", f"{commit}^{{commit}}").returncode != 0:
            return [f"commit {commit} is not in this repository"]
        where = f"since {commit}"
        # Only the files whose text differs can differ in fingerprint.
        differ = _git("diff", "--name-only", commit, "--", *sources, check=True).stdout.split()
        differ += _git("ls-files", "--others", "--exclude-standard", "--", *sources).stdout.split()
        changed = []
        for f in sorted(set(differ)):
            now = fingerprint(f, (ROOT / f).read_text(errors="replace")) if (ROOT / f).is_file() else None
            if now != _fingerprint_at(commit, f):
                changed.append(f)
    if not changed:
        return []
    return [f"changed {where}: {', '.join(changed[:6])}{' …' if len(changed) > 6 else ''}"]


def _busy_jiffies():
    """(busy, total) CPU time of the whole machine in clock ticks, from /proc/stat's first line."""
    with open("/proc/stat") as f:
        fields = [int(x) for x in f.readline().split()[1:]]
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
    return sum(fields) - idle, sum(fields)


class LoadWatch:
    """What the rest of the machine computed while a job (a child process) ran.

        with LoadWatch() as watch:
            subprocess.run(...)
        watch.record  # {"loadavg_before", "loadavg_after", "other_cores", "job_cores", "seconds", "quiet"}

    ``other_cores``: the machine's busy CPU time less the job's (its whole process tree once waited
    for), over the wall time, in cores. Off Linux (no /proc/stat) it is None and ``quiet`` is None.
    """

    def __enter__(self):
        self._linux = os.path.exists("/proc/stat")
        self._load = os.getloadavg()
        self._children = resource.getrusage(resource.RUSAGE_CHILDREN)
        self._self = resource.getrusage(resource.RUSAGE_SELF)
        self._jiffies = _busy_jiffies() if self._linux else None
        self._start = time.perf_counter()
        return self

    def __exit__(self, *exc):
        seconds = time.perf_counter() - self._start
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        own = resource.getrusage(resource.RUSAGE_SELF)
        job = sum(getattr(children, f) - getattr(self._children, f) for f in ("ru_utime", "ru_stime"))
        job += sum(getattr(own, f) - getattr(self._self, f) for f in ("ru_utime", "ru_stime"))
        other = None
        if self._linux:
            busy, _ = _busy_jiffies()
            machine = (busy - self._jiffies[0]) / os.sysconf("SC_CLK_TCK")
            other = max(machine - job, 0.0) / max(seconds, 1e-9)
        self.record = {
            "loadavg_before": [round(x, 2) for x in self._load],
            "loadavg_after": [round(x, 2) for x in os.getloadavg()],
            "job_cores": round(job / max(seconds, 1e-9), 3),
            "other_cores": None if other is None else round(other, 3),
            "seconds": round(seconds, 1),
            "quiet": None if other is None else other <= QUIET_OTHER_CORES,
        }
        return False


def annotate(path, sources, load):
    """Add ``sources`` (fingerprints) and ``load`` to the results file's ``machine`` block; a results file
    without one (a figure, a list) is left as it is. Returns whether it was annotated."""
    try:
        text = Path(path).read_text()
        data = json.loads(text)
    except (OSError, ValueError):
        return False
    if not isinstance(data, dict) or not isinstance(data.get("machine"), dict):
        return False
    data["machine"]["sources"] = source_hashes(sources)
    data["machine"]["load"] = load
    # Kept in the file's own indentation, so that the diff shows only what was added.
    second = text.split("\n", 2)[1] if text.count("\n") > 1 else ""
    indent = max(len(second) - len(second.lstrip(" ")), 1)
    Path(path).write_text(json.dumps(data, indent=indent) + "\n")
    return True
