"""The layers hold: the core imports nothing else of the project, the offline tools load neither
rclpy nor numba, the graph's processes no numba, and every console script names a main() that
exists."""

from __future__ import annotations

import ast
import importlib
import resource
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OFFLINE = ("clnn_ros.analysis.analyze", "clnn_ros.bag", "clnn_ros.live.echo",
           "clnn_ros.live.topics", "clnn_ros.graph.names", "clnn_ros.graph.qos",
           "clnn_ros.graph.fields")


def test_the_core_imports_nothing_outside_it():
    for path in sorted((ROOT / "clnn_ros" / "core").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                assert node.level <= 1, f"{path.name}: from {'.' * node.level}{node.module}"
                assert node.level or not (node.module or "").startswith("clnn_ros"), path.name
            elif isinstance(node, ast.Import):
                assert not any(a.name.startswith("clnn_ros") for a in node.names), path.name


def test_offline_tools_load_neither_rclpy_nor_numba():
    check = (f"import sys, {', '.join(OFFLINE)}; "
             "print(sorted(m for m in ('rclpy', 'numba') if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True,
                            check=True).stdout.strip()
    assert loaded == "[]"
    # CPU time, not wall time: other test runs share the machine's cores
    before = cpu_seconds_of_children()
    subprocess.run([sys.executable, "-m", "clnn_ros.analysis", "--help"], capture_output=True,
                   check=True)
    assert cpu_seconds_of_children() - before < 1.0


def test_the_graphs_processes_load_no_numba():
    """Numba is the batch engine's alone: in each of a graph's processes it would be two thirds
    of the start-up (core.jitable)."""
    modules = ["clnn_ros.run_all", "clnn_ros.processes.composed", "clnn_ros.nodes.recorder",
               *(f"clnn_ros.nodes.{name}" for name in ("environment", "encoder", "reward",
                                                       "agent", "trial_manager"))]
    check = f"import sys, {', '.join(modules)}; print('numba' in sys.modules)"
    loaded = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True,
                            check=True).stdout.strip()
    assert loaded == "False"


def cpu_seconds_of_children() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def test_console_scripts_name_a_main():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    for command, target in scripts.items():
        module, function = target.split(":")
        assert callable(getattr(importlib.import_module(module), function)), command


def imported_modules(path: Path, package: str) -> set[str]:
    """The absolute names of the project modules `path` (a module of `package`) imports."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                found.add(f"{base}.{node.module}" if node.module else base)
                found.update(f"{base}.{alias.name}" for alias in node.names if not node.module)
            else:
                found.add(node.module or "")
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return {name for name in found if name.startswith("clnn_ros")}


def test_the_contract_room_imports_no_ros():
    """clnn_ros.graph is what every caller agrees on: offline tools read it without rclpy."""
    modules = [f"clnn_ros.graph.{p.stem}" for p in (ROOT / "clnn_ros" / "graph").glob("*.py")]
    check = (f"import sys, {', '.join(modules)}; "
             "print(sorted(m for m in sys.modules if m.split('.')[0] in "
             "('rclpy', 'clnn_ros_msgs', 'numba')))")
    loaded = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True,
                            check=True).stdout.strip()
    assert loaded == "[]"


def test_run_all_loads_no_ros_and_no_node_in_process_mode():
    check = ("import sys, clnn_ros.run_all; print('rclpy' in sys.modules, "
             "sorted(m for m in sys.modules if m.startswith('clnn_ros.nodes')))")
    loaded = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True,
                            check=True).stdout.strip()
    assert loaded == "False []"


def test_no_node_module_imports_another():
    """Each node reads alone: what nodes use besides clnn_ros.graph is the glue module, the
    cart-pole's drawing (markers) and the trial manager's result files (trial_files): helpers,
    not nodes."""
    nodes = ROOT / "clnn_ros" / "nodes"
    for path in sorted(nodes.glob("*.py")):
        others = {f"clnn_ros.nodes.{p.stem}" for p in nodes.glob("*.py")} - \
            {f"clnn_ros.nodes.{path.stem}", "clnn_ros.nodes.glue", "clnn_ros.nodes.markers",
             "clnn_ros.nodes.trial_files", "clnn_ros.nodes.__init__"}
        assert not imported_modules(path, "clnn_ros.nodes") & others, path.name


def test_no_project_file_is_past_400_lines():
    for path in sorted((ROOT / "clnn_ros").rglob("*.py")):
        assert len(path.read_text().splitlines()) <= 400, path.relative_to(ROOT)


# The import directions of the README's table: each part of clnn_ros (a folder, or a module at
# the top) and the other parts it may import.
MAY_IMPORT = {
    "core": set(), "cli": set(), "files": set(), "figures": set(),
    "batch": {"core"},
    "task_batch": {"core", "batch", "tasks"},
    "baselines": {"core"},
    "tasks": {"core"},
    "reproduce": {"core", "batch", "task_batch", "baselines", "tasks", "figures", "cli"},
    "graph": {"core"},
    "session": {"core", "graph"},
    "bag": {"graph", "files", "cli"},
    "nodes": {"core", "graph", "session", "bag", "files", "tasks"},
    "processes": {"core", "graph", "session", "files", "bag", "nodes", "tasks"},
    "run_all": {"core", "graph", "session", "processes", "bag", "cli", "files", "tasks"},
    "analysis": {"core", "graph", "bag", "files", "cli", "figures"},
    "check_env": {"core", "graph", "session"},
    "live": {"graph", "bag", "check_env", "session", "cli"},
    "lab": {"core", "graph", "session", "cli"},
}


def part_of(module: str) -> str:
    return module.split(".")[1] if module.count(".") else module


def test_each_part_imports_only_what_the_readme_says_and_none_upwards():
    found = {}
    for path in sorted((ROOT / "clnn_ros").rglob("*.py")):
        if path.parent == ROOT / "clnn_ros" and path.name == "__init__.py":
            continue  # the package's own, empty
        module = ".".join(path.relative_to(ROOT).with_suffix("").parts)
        package = module.rsplit(".", 1)[0]
        part = part_of(module)
        imports = {part_of(m) for m in imported_modules(path, package)
                   if m.startswith("clnn_ros.")} - {part}
        assert imports <= MAY_IMPORT[part], \
            f"{module} imports {sorted(imports - MAY_IMPORT[part])}"
        found.setdefault(part, set()).update(imports)
    assert set(found) == set(MAY_IMPORT)  # every part is in the table
    # the table itself has no cycle: its parts sort so that each imports only earlier ones
    ordered, left = [], dict(MAY_IMPORT)
    while left:
        ready = [part for part, uses in left.items() if uses <= set(ordered)]
        assert ready, f"a cycle among {sorted(left)}"
        ordered += ready
        for part in ready:
            del left[part]
