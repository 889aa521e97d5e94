"""The package's layout: its modules import one another without cycles.

A module that imports another which (directly or through others) imports it back
runs half-initialised, hides which concept depends on which, and forces lazy
imports inside functions. The import graph is read from the source with `ast`, so
imports inside functions count too. Importing the package runs no JAX computation.
"""

import ast
import pathlib
import subprocess
import sys

import pytest

import jaxrot


PACKAGE_DIR = pathlib.Path(jaxrot.__file__).parent


def module_names(root: pathlib.Path, package: str) -> dict[str, pathlib.Path]:
    """Every module under ``root`` by dotted name (a package by its own name, not ``.__init__``)."""
    names = {}
    for path in sorted(root.rglob("*.py")):
        parts = [package, *path.relative_to(root).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts.pop()
        names[".".join(parts)] = path
    return names


def _resolve(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    """The absolute name of a ``from ... import`` statement's module."""
    if node.level == 0:
        return node.module or ""
    # ``from .`` in a package's ``__init__`` means the package itself, elsewhere the enclosing package.
    base = module.split(".")
    base = base[: len(base) - node.level + (1 if is_package else 0)]
    return ".".join([*base, node.module] if node.module else base)


def import_graph(root: pathlib.Path, package: str) -> dict[str, set[str]]:
    """Module → the modules of the same package it imports, at any depth of its source.

    ``from a import b`` counts as importing ``a.b`` where that is a module, else ``a``.
    The implicit import of a module's parent packages does not count: every module
    would then import the package's ``__init__``, which imports the public ones.
    """
    modules = module_names(root, package)
    graph = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        edges = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(node, name, path.name == "__init__.py")
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
            else:
                continue
            for target in targets:
                # ``import jaxrot.x.y`` imports the deepest of its prefixes that is a module here.
                while target and target not in modules:
                    target = target.rpartition(".")[0]
                if target and target != name:
                    edges.add(target)
        graph[name] = edges
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle as ``[a, b, ..., a]``, or None if the graph is acyclic."""
    done, stack, on_stack = set(), [], set()

    def visit(node):
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt in on_stack:
                return [*stack[stack.index(nxt) :], nxt]
            if nxt not in done:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        on_stack.discard(stack.pop())
        done.add(node)
        return None

    for node in sorted(graph):
        if node not in done:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


def test_jaxrot_import_graph_is_acyclic():
    graph = import_graph(PACKAGE_DIR, "jaxrot")
    # The graph was read: the rollout imports its core and the schemes package its schemes.
    assert "jaxrot._integrate._run" in graph["jaxrot._integrate._rollout"]
    assert "jaxrot.schemes.zhao" in graph["jaxrot.schemes"]
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


@pytest.mark.parametrize(
    "files, cycle",
    [
        # A function-level import closing the cycle, as `rollout` once imported `chunked_rollout`.
        (
            {
                "__init__.py": "",
                "a.py": "from .b import g\n",
                "b.py": "def g():\n    from .a import f\n",
            },
            ["pkg.a", "pkg.b", "pkg.a"],
        ),
        # Through a subpackage, with ``from .. import module`` and an absolute import.
        (
            {
                "__init__.py": "from . import a\n",
                "a.py": "from .sub import c\n",
                "sub/__init__.py": "",
                "sub/c.py": "from .. import d\n",
                "d.py": "import pkg.a\n",
            },
            ["pkg.a", "pkg.sub.c", "pkg.d", "pkg.a"],
        ),
        ({"__init__.py": "from . import a\n", "a.py": "from .b import x\n", "b.py": "x = 1\n"}, None),
    ],
)
def test_find_cycle_sees_cycles(tmp_path, files, cycle):
    for name, text in files.items():
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    assert find_cycle(import_graph(tmp_path, "pkg")) == cycle


def test_importing_jaxrot_starts_no_jax_backend():
    """A program configures JAX after its imports (``jax_num_cpu_devices``, ``jax.distributed``):
    a module that computes with JAX at import (a table checked with ``jnp``) starts the backend
    first and that configuration then raises. Measured: the exponential tableaux' import-time check
    did, and tests/test_multiprocess.py's workers failed."""
    modules = sorted(n for n in module_names(PACKAGE_DIR, "jaxrot") if "__main__" not in n)
    program = (
        "import importlib, jax\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        "jax.config.update('jax_num_cpu_devices', 2)\n"
    )
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
