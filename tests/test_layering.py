"""The floors of docs/architecture.md: every module imports only from its own floor or below; drivers import no labctl.

Checked two ways: an AST scan of every import statement (including imports inside functions and under
TYPE_CHECKING), and a fresh interpreter that imports the drivers and must not have loaded any labctl module.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# longest matching prefix wins; a new top-level module must be given its floor here
FLOORS: dict[str, int] = {
    "labctl": 0, "labctl.errors": 0, "labctl.data": 0,
    "labctl.physics": 1, "drivers": 1,
    "labctl.events": 2, "labctl.processing": 2, "labctl.protocol": 2, "labctl.protocols": 2, "labctl.storage": 2,
    "labctl.discrepancy": 2, "labctl.backends": 2, "labctl.hardware": 2, "labctl.stiffness_table": 2,
    "labctl.engine": 3, "labctl.report": 3, "labctl.uff": 3, "labctl.campaign": 3, "labctl.reprocess": 3,
    "labctl.recording": 3,
    "labctl.calibration": 2, "labctl.archive": 3, "labctl.planning": 3, "labctl.programme": 3, "labctl.compare": 3,
    "labctl.tui": 4,
    "labctl.cli": 5, "labctl.__main__": 5,
}
OWN = ("labctl", "drivers")


def floor(module: str) -> int | None:
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        prefix = ".".join(parts[:n])
        if prefix in FLOORS and (n > 1 or module == prefix or parts[0] == "drivers"):
            return FLOORS[prefix]
    return None


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def imports(text: str, module: str, is_package: bool = False) -> list[tuple[int, str]]:
    """(line, absolute module) for every import of our own packages in one module's source."""
    package = module if is_package else module.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            targets = [f"{base}.{a.name}" for a in node.names]
            out += [(node.lineno, t if floor(t) is not None and t.startswith(base) else base) for t in targets]
    return [(line, m) for line, m in out if m.split(".")[0] in OWN]


def violations(text: str, module: str, is_package: bool = False) -> list[str]:
    """Imports of ``module`` that run up a floor, or from drivers into labctl."""
    mine, out = floor(module), []
    for line, target in imports(text, module, is_package):
        theirs = floor(target)
        if module.split(".")[0] == "drivers" and target.split(".")[0] == "labctl":
            out.append(f"{module}:{line} drivers import {target}")
        elif mine is not None and theirs is not None and theirs > mine:
            out.append(f"{module}:{line} floor {mine} imports {target} (floor {theirs})")
    return out


def sources() -> list[Path]:
    return sorted(p for pkg in OWN for p in (ROOT / pkg).rglob("*.py"))


def test_every_module_has_a_floor():
    missing = [module_name(p) for p in sources() if floor(module_name(p)) is None]
    assert not missing, f"give these modules a floor in tests/test_layering.py FLOORS: {missing}"


def test_no_import_runs_up_a_floor_and_drivers_import_no_labctl():
    found = [v for p in sources() for v in violations(p.read_text(), module_name(p), p.name == "__init__.py")]
    assert not found, "\n".join(found)


def test_importing_the_drivers_loads_no_labctl_module():
    code = (
        "import sys, pkgutil, importlib, drivers\n"
        "for m in pkgutil.walk_packages(drivers.__path__, 'drivers.'):\n"
        "    try:\n"
        "        importlib.import_module(m.name)\n"
        "    except ImportError as exc:\n"  # an optional vendor library missing is not our concern here
        "        if 'labctl' in str(exc): raise\n"
        "print(sorted(n for n in sys.modules if n == 'labctl' or n.startswith('labctl.')))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"


def test_the_scan_sees_upward_and_relative_imports():
    assert floor("labctl.physics.rig") == 1 and floor("labctl.cli.simulate") == 5 and floor("drivers.sim.twin") == 1
    assert floor("labctl.nonexistent") is None and floor("labctl") == 0
    up = "def f():\n    from ..engine import Engine\n"
    assert violations(up, "labctl.physics.world") == [
        "labctl.physics.world:2 floor 1 imports labctl.engine.Engine (floor 3)"]
    assert violations("from labctl import physics\n", "drivers.sim.twin") == [
        "drivers.sim.twin:1 drivers import labctl.physics"]
    assert violations("from . import rig\nfrom labctl.errors import InputError\n", "labctl.physics", True) == []
    assert violations("import labctl.tui.app\n", "labctl.engine.runner") == [
        "labctl.engine.runner:1 floor 3 imports labctl.tui.app (floor 4)"]


def test_only_storage_imports_h5py():
    """The campaign file format has one owner: nothing outside labctl/storage opens HDF5 itself."""
    found = []
    for path in sources():
        module = module_name(path)
        if module.startswith("labctl.storage"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            found += [f"{module}:{node.lineno} imports {n}" for n in names if n.split(".")[0] == "h5py"]
    assert not found, "\n".join(found)
