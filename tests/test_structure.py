"""The package's layout: its modules import one another without cycles, and its rooms stand in floors.

A module that imports another which (directly or through others) imports it back
runs half-initialised, hides which concept depends on which, and forces lazy
imports inside functions. The import graph is read from the source with `ast`, so
imports inside functions count too. Importing the package runs no JAX computation.

A room is a module directly under jaxrot/ or a subpackage. `FLOORS` orders the rooms from the ground
up: a room imports only from rooms on lower floors, so the house reads bottom to top. The top level
holds at most 12 files, no module is over 400 lines, no jaxrot import hides inside a function (the
command line aside), and `jaxrot.__all__` lists every public name of the package.
"""

import ast
import pathlib
import subprocess
import sys
import types

import pytest

import jaxrot


PACKAGE_DIR = pathlib.Path(jaxrot.__file__).parent
# Rooms that import an optional dependency (an extra): `import jaxrot` never imports them.
OPTIONAL = ("jaxrot.jax_md",)


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


def _import_targets(node: ast.AST, module: str, is_package: bool, modules) -> list[str]:
    """The modules of the package (keys of ``modules``) that an import statement imports, else []."""
    if isinstance(node, ast.Import):
        targets = [alias.name for alias in node.names]
    elif isinstance(node, ast.ImportFrom):
        base = _resolve(node, module, is_package)
        targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
    else:
        return []
    found = []
    for target in targets:
        # ``import jaxrot.x.y`` imports the deepest of its prefixes that is a module here.
        while target and target not in modules:
            target = target.rpartition(".")[0]
        if target:
            found.append(target)
    return found


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
        is_package = path.name == "__init__.py"
        graph[name] = {
            target
            for node in ast.walk(tree)
            for target in _import_targets(node, name, is_package, modules)
            if target != name
        }
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


def test_importing_jaxrot_starts_no_jax_backend_and_changes_no_setting():
    """A program configures JAX after its imports (``jax_num_cpu_devices``, ``jax.distributed``):
    a module that computes with JAX at import (a table checked with ``jnp``) starts the backend
    first and that configuration then raises. Measured: the exponential tableaux' import-time check
    did, and tests/test_multiprocess.py's workers failed."""
    # jaxrot.jax_md, the optional adapter, imports jax_md, which computes at import (its shapes' tables):
    # a user imports it on purpose, after configuring JAX.
    modules = sorted(
        n for n in module_names(PACKAGE_DIR, "jaxrot") if "__main__" not in n and not n.startswith(OPTIONAL)
    )
    # Nor does an import change a global JAX setting (x64, the compilation cache: DESIGN.md, "Compile
    # time"): the user switches those on, in one line (docs/performance.md).
    program = (
        "import importlib, jax\n"
        "before = dict(jax.config.values)\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        "changed = sorted(k for k, v in jax.config.values.items() if before.get(k) != v)\n"
        "assert not changed, f'importing jaxrot changed JAX settings {changed}'\n"
        "jax.config.update('jax_num_cpu_devices', 2)\n"
    )
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]


# The rooms from the ground up. A room imports only from the floors below its own (never from its
# floor, nor above): the ground floor imports nothing of jaxrot; the package's face and the command
# line, on top, may import anything. A new room must be placed here.
FLOORS = [
    ["_core"],  # NaN-safe helpers, compile settings, the generic value checks
    ["quaternion"],  # the rotation
    ["_state", "_inertia"],  # a body: its state, its inertia (and the inertia's checks)
    ["_particles", "_validation", "_pivot"],  # many bodies; the checks of a run; a top's pivot inertia
    ["torques", "_free_body", "_fluid", "diagnostics"],  # what turns a body, the medium, measures
    ["schemes", "analytic", "scenes"],  # one step; exact motions; problems
    ["_integrate"],  # every loop, and the binder that decides which scheme fits which call
    ["_diffrax", "stability", "_fit", "jax_md"],  # diffrax face; step-size limits; fitting; jax_md adapter
    ["comparison"],  # all measurement
    ["__init__", "__main__"],  # the package's face, the command line
]


def room_of(module: str, package: str) -> str:
    """The room of a dotted module name: its first part under ``package`` (``__init__`` for the package)."""
    parts = module.split(".")
    assert parts[0] == package, module
    return parts[1] if len(parts) > 1 else "__init__"


def upward_imports(graph: dict[str, set[str]], floors: list[list[str]], package: str) -> list[str]:
    """``"a -> b"`` for each import from a module ``a`` to a module ``b`` of another room on the same or
    a higher floor (``floors`` lists the rooms from the ground up)."""
    floor = {room: level for level, rooms in enumerate(floors) for room in rooms}
    found = []
    for module, targets in sorted(graph.items()):
        room = room_of(module, package)
        for target in sorted(targets):
            other = room_of(target, package)
            if other != room and floor[other] >= floor[room]:
                found.append(f"{module} -> {target}")
    return found


def test_every_room_is_on_one_floor():
    rooms = {room_of(name, "jaxrot") for name in module_names(PACKAGE_DIR, "jaxrot")}
    placed = [room for rooms_ in FLOORS for room in rooms_]
    assert len(placed) == len(set(placed)), "a room is on two floors"
    assert rooms - set(placed) == set(), "place the new room(s) on a floor of FLOORS"
    assert set(placed) - rooms == set(), "FLOORS names a room that is gone"


def test_no_import_runs_up_the_floors():
    graph = import_graph(PACKAGE_DIR, "jaxrot")
    # The graph was read: the binder of the loops imports the schemes, a floor below.
    assert "jaxrot.schemes" in graph["jaxrot._integrate._bind"]
    assert upward_imports(graph, FLOORS, "jaxrot") == []


def test_upward_imports_sees_imports_up_and_across(tmp_path):
    files = {
        "__init__.py": "from . import top\n",
        "low.py": "def f():\n    from .sub import c\n",  # up, inside a function
        "mid.py": "from . import low\nfrom .side import x\n",  # down (fine), across (not)
        "side.py": "x = 1\n",
        "sub/__init__.py": "",
        "sub/c.py": "from .. import mid\n",
        "top.py": "import pkg.sub.c\n",
    }
    for name, text in files.items():
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    floors = [["low"], ["mid", "side"], ["sub"], ["top"], ["__init__"]]
    assert upward_imports(import_graph(tmp_path, "pkg"), floors, "pkg") == [
        "pkg.low -> pkg.sub.c",
        "pkg.mid -> pkg.side",
    ]


def test_the_top_level_holds_at_most_12_files():
    files = sorted(path.name for path in PACKAGE_DIR.glob("*.py"))
    assert len(files) <= 12, f"{len(files)} files directly under jaxrot/: {files}; give a concept a room"


def test_no_module_is_over_400_lines():
    long = {
        str(path.relative_to(PACKAGE_DIR.parent)): n
        for path in PACKAGE_DIR.rglob("*.py")
        if (n := len(path.read_text().splitlines())) > 400
    }
    assert long == {}, "split these modules by concept"


def test_no_jaxrot_import_inside_a_function():
    """Imports at the top of a module say what it depends on; one inside a function hides a cycle or a
    misplaced concept. The command line (``__main__.py``) may import late, to start fast."""
    modules = module_names(PACKAGE_DIR, "jaxrot")
    late = []
    for name, path in modules.items():
        if path.name == "__main__.py":
            continue
        tree = ast.parse(path.read_text(), filename=str(path))
        for function in ast.walk(tree):
            if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                for node in ast.walk(function):
                    if _import_targets(node, name, path.name == "__init__.py", modules):
                        late.append(f"{path.relative_to(PACKAGE_DIR.parent)}:{node.lineno}")
    assert late == []


def test_optional_rooms_stay_out_of_import_jaxrot():
    """``import jaxrot`` imports no optional room (nor its dependency): ``import jaxrot.jax_md`` does."""
    program = (
        "import sys, jaxrot\n"
        "print(sorted(m for m in sys.modules if m.startswith(('jax_md', 'jaxrot.jax_md'))))"
    )
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip() == "[]"


def test_all_lists_every_public_name():
    """`jaxrot.__all__` is every public name bound in the package but its submodules (and other modules):
    a name added to jaxrot/__init__.py without being listed fails here, and so does a listed name gone."""
    public = {
        name
        for name, value in vars(jaxrot).items()
        if not name.startswith("_") and not isinstance(value, types.ModuleType)
    }
    assert len(jaxrot.__all__) == len(set(jaxrot.__all__)), "a name is listed twice"
    assert set(jaxrot.__all__) == public
    assert list(jaxrot.__all__) == sorted(jaxrot.__all__)
