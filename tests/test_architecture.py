"""The package's shape (DESIGN §9): no import cycles, layers that point one way, no machine paths.

Imports are read from the source (module level *and* inside functions), resolved to selfnav
modules, and checked as a graph.
"""
import ast
import re
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "selfnav"

#: modules still being moved into their layer (issue 13 takes the moving-base driver out of the
#: attitude reader); empty this set when that lands
PENDING = set()

#: layer of each top-level module or subpackage (lower may not import higher)
LAYERS = {
    "types": 0, "units": 0, "errors": 0,
    "earth": 1, "attitude": 1, "datum": 1, "kernels": 1, "igrf": 1, "cluster": 1, "axes": 1,
    "correlation": 1, "quantiles": 1,
    "axes_detect": 1,
    "io": 2, "sensors": 2,
    "allan": 3, "latitude": 3, "moving": 3, "moving_budget": 3, "ins": 3, "roads": 3, "gnss": 3,
    "sim": 3, "moving_driver": 4,
    "seed004": 4, "solution": 4, "summary": 4, "evaluation": 4, "report": 4, "montecarlo": 4,
    "api": 5, "api_gnss": 5, "demo": 6, "campaigns": 6, "cli": 7, "__main__": 8,
}


def _modules():
    out = {}
    for p in SRC.rglob("*.py"):
        rel = p.relative_to(SRC.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _imports(name, path, modules):
    """selfnav modules imported anywhere in ``path`` (package imports resolved to submodules)."""
    tree = ast.parse(path.read_text())
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("selfnav"):
                    found.add(a.name)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            if not base.startswith("selfnav"):
                continue
            for a in node.names:
                sub = f"{base}.{a.name}"
                found.add(sub if sub in modules else base)
    # the lazy API table of the package __init__ (strings naming modules)
    if name == "selfnav":
        found |= {m for m in re.findall(r'"(selfnav\.[\w.]+)"', path.read_text()) if m in modules}
    return {m for m in found if m in modules and m != name}


@pytest.fixture(scope="module")
def graph():
    mods = _modules()
    return {n: _imports(n, p, mods) for n, p in mods.items()}


def _top(mod):
    parts = mod.split(".")
    return parts[1] if len(parts) > 1 else ""


def test_no_import_cycles(graph):
    """Tarjan's strongly connected components: every one must be a single module. The package
    ``selfnav`` itself is left out (its lazy API table names the modules it re-exports)."""
    g = {k: {v for v in vs if v != "selfnav"} for k, vs in graph.items() if k != "selfnav"}
    index, low, stack, on, comps = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in g.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            comps.append(comp)

    for v in sorted(g):
        if v not in index:
            visit(v)
    cycles = [sorted(c) for c in comps if len(c) > 1]
    assert not cycles, f"import cycles: {cycles}"


def test_layers_point_one_way(graph):
    bad = []
    for mod, deps in graph.items():
        if mod == "selfnav" or _top(mod) not in LAYERS or mod in PENDING:
            continue
        for d in deps:
            if d == "selfnav" or _top(d) not in LAYERS or _top(d) == _top(mod):
                continue
            if LAYERS[_top(d)] > LAYERS[_top(mod)]:
                bad.append(f"{mod} -> {d}")
    assert not bad, "imports against the layers: " + ", ".join(sorted(bad))


def test_every_module_has_a_layer(graph):
    missing = sorted({_top(m) for m in graph if m != "selfnav"} - set(LAYERS))
    assert not missing, f"modules without a layer in DESIGN §9: {missing}"


def test_readers_import_no_algorithm(graph):
    allowed = {"types", "units", "errors", "earth", "attitude", "datum", "axes", "io"}
    bad = [f"{m} -> {d}" for m, deps in graph.items() if m.startswith("selfnav.io")
           and m not in PENDING for d in deps if _top(d) not in allowed]
    assert not bad, bad


def test_no_private_names_across_modules():
    bad = []
    pending = {str(SRC.parent / m.replace(".", "/")) + ".py" for m in PENDING}
    for p in SRC.rglob("*.py"):
        if str(p) in pending:
            continue
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("selfnav"):
                bad += [f"{p.name}: {node.module}.{a.name}" for a in node.names
                        if a.name.startswith("_") and not a.name.startswith("__")]
    assert not bad, bad


def test_no_machine_paths():
    pat = re.compile(r"['\"](/work/|/home/|/root/|/tmp/|[A-Z]:\\\\)")
    bad = [str(p) for p in SRC.rglob("*.py") if pat.search(p.read_text())]
    assert not bad, bad
