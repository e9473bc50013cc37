"""The layers import downwards only: no module of a package imports itself back through others, the
library imports none of the packages built on it, and no module reads another module's private names.

Read from the source with ``ast`` (no imports run), counting every import statement, those inside
functions included: a deferred import hides a loop from the interpreter but not from a reader.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PRODUCT = ("vfcore", "vfvideo", "worker", "service")
#: What each package may import from the others (service sits on top and may import any).
ALLOWED = {"vfcore": set(), "vfvideo": {"vfcore"}, "worker": {"vfcore"}}


def _modules(packages) -> dict[str, Path]:
    out = {}
    for pkg in packages:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path):
    """(line, imported module, imported names) of each import statement, relative ones resolved."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name, ()
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module
            yield node.lineno, module, tuple(alias.name for alias in node.names)


def _graph(packages) -> dict[str, set[str]]:
    """Module -> the modules of ``packages`` it imports (``from pkg import sub`` counts as ``pkg.sub``)."""
    mods = _modules(packages)
    edges = {m: set() for m in mods}
    for m, path in mods.items():
        for _, module, names in _imports(m, path):
            targets = [f"{module}.{n}" if f"{module}.{n}" in mods else module for n in names] or [module]
            for t in targets:
                while t not in mods and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t in mods and t != m:
                    edges[m].add(t)
    return edges


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    counter = 0
    for root in edges:
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(edges[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    x = stack.pop()
                    on_stack.discard(x)
                    comp.append(x)
                    if x == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_the_cycle_finder_sees_a_loop_through_a_deferred_import():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


@pytest.mark.parametrize("packages", [("vfcore",), ("vfcore", "vfvideo", "worker"), PRODUCT])
def test_no_import_cycles(packages):
    cycles = _cycles(_graph(packages))
    assert not cycles, f"modules that import each other (directly or around a loop): {cycles}"


def test_the_command_line_and_the_routes_never_import_each_other():
    """They share the request types and their bounds through ``service.api_models``: a command that imported a
    route (or a route a command) would tie the CLI to the HTTP layer."""
    edges = _graph(("service",))
    cli = {m for m in edges if m.split(".")[-1].startswith("cli")}
    routes = {m for m in edges if m.startswith("service.routers")}
    bad = sorted(
        f"{a} imports {b}" for a in edges for b in edges[a] if (a in cli and b in routes) or (a in routes and b in cli)
    )
    assert not bad, bad


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_a_package_imports_only_the_layers_below_it(package):
    others = set(PRODUCT) - {package} - ALLOWED[package]
    bad = [
        f"{path.relative_to(ROOT)}:{line} imports {module}"
        for m, path in _modules([package]).items()
        for line, module, _ in _imports(m, path)
        if module and module.split(".")[0] in others
    ]
    assert not bad, bad


def test_no_module_imports_another_modules_private_names():
    """``from x import _name`` couples a module to another's internals; a private module of the same
    package (``from .solver import _kernels``) is that package's own business."""
    mods = _modules(PRODUCT)
    bad = []
    for m, path in mods.items():
        for line, module, names in _imports(m, path):
            for n in names:
                if not n.startswith("_") or n.startswith("__"):
                    continue
                if f"{module}.{n}" in mods and module.split(".")[0] == m.split(".")[0]:
                    continue
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {n} from {module}")
    assert not bad, bad


DOUBLES = {p.stem for p in (ROOT / "tests" / "doubles").glob("*.py")}


def test_the_product_ships_no_test_doubles():
    """The analytic stand-ins (``tests/doubles``) are not physics: they plug into the worker and the service
    through ``worker.models``, so no product module imports them and the only model the product registers is
    the finite-element one."""
    mods = _modules(PRODUCT)
    users = [
        f"{path.relative_to(ROOT)}:{line}"
        for m, path in mods.items()
        for line, module, _ in _imports(m, path)
        if module.split(".")[0] in DOUBLES
    ]
    assert not users, users
    registered = {
        node.args[0].value
        for path in mods.values()
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.Call)
        and getattr(node.func, "id", None) == "register_model"
        and node.args
        and isinstance(node.args[0], ast.Constant)
    }
    assert registered == {"fe"}, registered
