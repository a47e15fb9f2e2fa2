"""The package's modules import each other without cycles (type-checking imports included)."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / 'sensor_comp'


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix('').parts)
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def _imports(path: Path, name: str, modules: set[str]) -> set[str]:
    """Return the package modules ``path`` imports at module level or for type checking."""
    package = name.split('.') if path.name == '__init__.py' else name.split('.')[:-1]
    found = set()
    for node in ast.parse(path.read_text(encoding='utf-8')).body:
        for statement in node.body if isinstance(node, ast.If) else [node]:
            if isinstance(statement, ast.ImportFrom):
                base = '.'.join(package[:len(package) - statement.level + 1]
                                + [statement.module or '']).strip('.') \
                    if statement.level else statement.module
                for alias in statement.names:
                    full = f'{base}.{alias.name}'
                    found.add(full if full in modules else base)
            elif isinstance(statement, ast.Import):
                found.update(alias.name for alias in statement.names)
    return {m for m in found if m in modules and m != name}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Return the strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while not component or component[-1] != v:
                component.append(stack.pop())
                on_stack.discard(component[-1])
            if len(component) > 1:
                found.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_no_import_cycle():
    paths = {_module_name(p): p for p in PACKAGE.rglob('*.py')}
    graph = {name: _imports(path, name, set(paths)) for name, path in paths.items()}
    assert _cycles(graph) == []


def test_the_check_finds_a_cycle():
    assert _cycles({'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}}) == [['a', 'b', 'c']]
