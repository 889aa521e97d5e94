"""pytest plugin, a measuring tool (not loaded by the suite): per-test JAX compile counts and seconds
(trace, lower, XLA compile) and the persistent cache's hits, misses, writes and refusals (programs
with host callbacks are never written).

    JAXCOUNT_DIR=/tmp/counts PYTHONPATH=.:.ci python -m pytest -p compile_counts ...

Writes $JAXCOUNT_DIR/<pid>.json at session end (one per xdist worker; also after Ctrl-C): per-test
counters, and one record per backend compile: [test, module, cache key, seconds, kind], kind one of
hit/written/refused/nocache."""

import collections
import json
import logging
import os
import re
import time

import pytest


_cur = ["<collect>"]
_stats = collections.defaultdict(lambda: collections.Counter())
_records = []
_pending = {"key": None, "name": None, "kind": "nocache"}
_KEY = re.compile(r"for '([^']*)' with key '([^']*)'")


def _dur(event, secs, **kw):
    s = _stats[_cur[0]]
    short = event.rsplit("/", 1)[-1]
    s[short + "_s"] += secs
    s[short + "_n"] += 1
    if short == "backend_compile_duration":
        kind = _pending["kind"]
        if kind == "refused":
            s["refused_s"] += secs
        _records.append([_cur[0], _pending["name"] or kw.get("fun_name"), _pending["key"], secs, kind])
        _pending.update(key=None, name=None, kind="nocache")


def _ev(event, **kw):
    _stats[_cur[0]][event.rsplit("/", 1)[-1]] += 1


class _H(logging.Handler):
    def emit(self, rec):
        msg = rec.getMessage()
        s = _stats[_cur[0]]
        if "because it uses host callbacks" in msg:
            s["refused_callbacks"] += 1
            _pending["kind"] = "refused"
        elif "seconds to compile" in msg and "took at least" in msg:
            s["written"] += 1
            _pending["kind"] = "written"
        elif "Persistent compilation cache hit" in msg or "PERSISTENT COMPILATION CACHE MISS" in msg:
            kind = "hit" if "cache hit" in msg else "miss"
            s[kind] += 1
            m = _KEY.search(msg)
            if m:
                _pending.update(name=m.group(1), key=m.group(2))
            _pending["kind"] = kind
        elif "because it took <" in msg:
            s["refused_fast"] += 1


def pytest_configure(config):
    import jax

    jax.monitoring.register_event_duration_secs_listener(_dur)
    jax.monitoring.register_event_listener(_ev)
    lg = logging.getLogger("jax._src.compiler")
    lg.setLevel(logging.DEBUG)
    lg.addHandler(_H())
    lg.propagate = False


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    _cur[0] = item.nodeid
    t = time.perf_counter()
    yield
    _stats[item.nodeid]["wall_s"] += time.perf_counter() - t
    _cur[0] = "<between>"


def pytest_sessionfinish(session):
    d = os.environ.get("JAXCOUNT_DIR")
    if not d:
        return
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, f"{os.getpid()}.json"), "w") as f:
        json.dump({"stats": {k: dict(v) for k, v in _stats.items()}, "records": _records}, f)
