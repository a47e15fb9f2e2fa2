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


#: The core's packages in data-flow order: a stage imports only itself and earlier stages.
STAGES = ('shots', 'estimators', 'effects', 'compensation', 'identification', 'diagnosis',
          'report')
#: What the core may import from the rest of the package (no ROS, no I/O formats).
CORE_MAY_USE = {'sensor_comp.errors', 'sensor_comp.files', 'sensor_comp.lazy',
                'sensor_comp.sharing', 'sensor_comp.streams', 'sensor_comp.version',
                'sensor_comp.worker'}


def _all_imports(path: Path, name: str) -> set[str]:
    """Return every ``sensor_comp`` module ``path`` imports, function-level imports included."""
    package = name.split('.') if path.name == '__init__.py' else name.split('.')[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
        if isinstance(node, ast.ImportFrom):
            found.add('.'.join(package[:len(package) - node.level + 1]
                               + [node.module or '']).strip('.')
                      if node.level else node.module or '')
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return {m for m in found if m.split('.')[0] == 'sensor_comp'}


def _stage(module: str) -> str | None:
    parts = module.split('.')
    return parts[2] if len(parts) > 2 and parts[1] == 'core' and parts[2] in STAGES else None


def test_data_flows_one_way_through_the_core():
    wrong = []
    for path in (PACKAGE / 'core').rglob('*.py'):
        name = _module_name(path)
        for target in _all_imports(path, name):
            if not target.startswith('sensor_comp.core'):
                if target not in CORE_MAY_USE:
                    wrong.append(f'{name} imports {target}')
            elif _stage(name) and _stage(target) and (
                    STAGES.index(_stage(target)) > STAGES.index(_stage(name))):
                wrong.append(f'{name} imports the later stage {target}')
    assert wrong == []
