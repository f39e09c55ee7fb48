"""The package layout: dependencies run one way, modules stay small and documented.

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


#: lidar_env's subpackages from the bottom up: each may import only those before it. The top
#: modules (``config``, ``scenes``, ``env_views``, ``env``) may import every subpackage, and
#: ``vector`` (the batched env) and ``faults`` (wrappers over the env) the top modules too.
ENV_LAYERS = ("core", "routes", "world", "sensors", "vehicle", "movers", "rendering")
ENV_TOP = {"lidar_env.config", "lidar_env.scenes", "lidar_env.env_views", "lidar_env.env",
           "lidar_env.moved_modules"}


def _env_layer(module: str) -> int | None:
    parts = module.split(".")
    if parts[0] != "lidar_env" or len(parts) < 2:
        return None
    if parts[1] in ENV_LAYERS:
        return ENV_LAYERS.index(parts[1])
    if module in ENV_TOP:
        return len(ENV_LAYERS)
    return len(ENV_LAYERS) + 1 if parts[1] in ("vector", "faults") else None


def test_env_subpackages_import_only_downwards() -> None:
    upward = [f"{module} imports {target}"
              for module, targets in GRAPH.items() if (layer := _env_layer(module)) is not None
              for target in targets
              if (other := _env_layer(target)) is not None and other > layer]
    assert not upward, ("imports against the layer order " + " < ".join(ENV_LAYERS)
                        + " < top modules < vector, faults:\n" + "\n".join(upward))


def test_the_base_layer_imports_nothing_of_the_project() -> None:
    outside = [f"{module} imports {target}" for module, targets in GRAPH.items()
               if module.startswith("lidar_env.core") for target in targets
               if not target.startswith("lidar_env.core")]
    assert not outside, "\n".join(outside)


def _faces() -> set[str]:
    """What estimators and agents may import from lidar_env: the package, its subpackages'
    ``__init__`` (their faces), the top modules and every module of the base layer."""
    faces = {"lidar_env", "lidar_env.config", "lidar_env.env", "lidar_env.vector",
             "lidar_env.faults"}
    faces.update(f"lidar_env.{layer}" for layer in ENV_LAYERS)
    faces.update(name for name in MODULES if name.startswith("lidar_env.core."))
    return faces


def test_estimators_and_agents_use_only_the_env_faces() -> None:
    faces = _faces()
    reaching = [f"{module} imports {target}" for module, targets in GRAPH.items()
                if module.split(".")[0] in ("estimators", "agents") for target in targets
                if target.startswith("lidar_env") and target not in faces]
    assert not reaching, ("import these from a face of lidar_env (" + ", ".join(sorted(faces))
                          + "):\n" + "\n".join(reaching))


def test_no_private_name_is_imported_from_another_module() -> None:
    found = []
    for name, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                private = [alias.name for alias in node.names if alias.name.startswith("_")
                           and not alias.name.startswith("__")]
                if private and node.module.split(".")[0] in PACKAGES:
                    found.append(f"{name} imports {', '.join(private)} from {node.module}")
    assert not found, "make these public or keep them in their module:\n" + "\n".join(found)


def test_nothing_in_the_project_imports_a_moved_path() -> None:
    from lidar_env.moved_modules import MOVED

    found = []
    for path in sorted(ROOT.glob("*/**/*.py")):
        if path.parts[len(ROOT.parts)] in (".venv", "site") or path.name == "moved_modules.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([alias.name for alias in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            if isinstance(node, ast.ImportFrom) and node.module in {"lidar_env", "estimators"}:
                names += [f"{node.module}.{alias.name}" for alias in node.names]
            found += [f"{path.relative_to(ROOT)}: {name} (now {MOVED[name]})"
                      for name in names if name in MOVED]
    assert not found, "\n".join(found)
