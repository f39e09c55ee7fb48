"""The package layout (issue 14): dependencies run one way, modules stay small and documented.

The import graph is read from the source with ``ast`` (nothing is imported), so a cycle or an
upward import is caught even where it would only fail at run time.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("agents", "estimators", "lidar_env")
MAX_LINES = 400
#: estimators' subpackages from the bottom up: each may import only those before it (and
#: ``base``, ``registry``, ``paths``, which every layer may use).
LAYERS = ("paper", "matching", "odometry", "slam", "mapping", "evaluation", "datasets",
          "leaderboard", "calibration")
SHARED = {"estimators", "estimators.base", "estimators.registry", "estimators.paths"}


def _modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """The project modules ``name`` imports (a name imported from a package counts as the
    submodule when there is one of that name)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            targets.add(base)
            targets.update(f"{base}.{alias.name}" for alias in node.names)
    return {t for t in targets if t in MODULES and t != name}


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _layer(module: str) -> int | None:
    parts = module.split(".")
    if parts[0] != "estimators" or len(parts) < 2 or parts[1] not in LAYERS:
        return None
    return LAYERS.index(parts[1])


def test_the_import_graph_has_no_cycles() -> None:
    state: dict[str, int] = {}  # 1 on the current path, 2 done
    cycles = []

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for target in sorted(GRAPH[node]):
            if state.get(target) == 1:
                cycles.append(" -> ".join(path[path.index(target):] + [target]))
            elif target not in state:
                visit(target, path + [target])
        state[node] = 2

    for module in sorted(GRAPH):
        if module not in state:
            visit(module, [module])
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def test_estimators_subpackages_import_only_downwards() -> None:
    upward = [f"{module} imports {target}"
              for module, targets in GRAPH.items() if (layer := _layer(module)) is not None
              for target in targets
              if (other := _layer(target)) is not None and other > layer]
    assert not upward, "imports against the layer order " + " < ".join(LAYERS) + ":\n" + (
        "\n".join(upward))


def test_shared_estimator_modules_import_no_subpackage() -> None:
    """``base``, ``registry`` and ``paths`` sit under every layer (the registry names its
    estimators as strings and imports them on first use)."""
    upward = [f"{module} imports {target}" for module in SHARED - {"estimators"}
              for target in GRAPH[module] if _layer(target) is not None]
    assert not upward, "\n".join(upward)


def test_the_env_imports_nothing_that_scores_it() -> None:
    offending = [f"{module} imports {target}" for module, targets in GRAPH.items()
                 if module.startswith("lidar_env") for target in targets
                 if target.startswith("estimators")]
    assert not offending, "\n".join(offending)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_every_module_is_small_and_documented(module: str) -> None:
    path = MODULES[module]
    relative = path.relative_to(ROOT).as_posix()
    tree = ast.parse(path.read_text())
    assert ast.get_docstring(tree), f"{relative} has no module docstring"
    lines = len(path.read_text().splitlines())
    assert lines <= MAX_LINES, f"{relative} has {lines} lines, over {MAX_LINES}"
