"""The package's layers: no import cycle between modules or between sub-packages, counting imports inside
functions, and no module of ``moiq_jax/algos`` over 300 lines."""

import ast
import pathlib

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "moiq_jax"
SUBPACKAGES = ("moiq_jax.algos", "moiq_jax.experts", "moiq_jax.envs")


def module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in PACKAGE.rglob("*.py")}


def imports(name: str) -> set[str]:
    """The moiq_jax modules ``name`` imports anywhere in its file: ``from pkg import sub`` counts as the
    sub-module, ``from pkg import thing`` as the package's ``__init__``."""
    found = set()
    tree = ast.parse(MODULES[name].read_text())
    package = name if MODULES[name].name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name in MODULES)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else []))
            if not base.startswith("moiq_jax"):
                continue
            for alias in node.names:
                found.add(f"{base}.{alias.name}" if f"{base}.{alias.name}" in MODULES else base)
    return found - {name}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as a list of nodes, or None."""
    state, stack = {}, []

    def visit(node):
        state[node] = "open"
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        state[node] = "done"
        stack.pop()
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def layer(name: str) -> str:
    return next((sub for sub in SUBPACKAGES if name == sub or name.startswith(sub + ".")), name)


def test_the_cycle_finder_finds_cycles():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_import_reading_counts_imports_inside_functions():
    assert "moiq_jax.envs" in imports("moiq_jax.config")  # imported inside Config.validate
    assert "moiq_jax.algos.offpolicy" in imports("moiq_jax.algos.moiq")


def test_no_import_cycle_between_modules():
    graph = {name: imports(name) for name in MODULES}
    assert find_cycle(graph) is None, " -> ".join(find_cycle(graph))


def test_no_import_cycle_between_subpackages():
    graph = {}
    for name in MODULES:
        graph.setdefault(layer(name), set()).update(layer(n) for n in imports(name) if layer(n) != layer(name))
    assert find_cycle(graph) is None, " -> ".join(find_cycle(graph))


@pytest.mark.parametrize("path", sorted((PACKAGE / "algos").glob("*.py")), ids=lambda p: p.name)
def test_algos_modules_are_at_most_300_lines(path):
    assert len(path.read_text().splitlines()) <= 300
