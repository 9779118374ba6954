"""The package's walls (temc_train/__init__.py): the library never imports the drivers,
probes or vector writers, and has no entry points; those live in the walls, each a command."""

import ast
import pathlib

import pytest

PKG = pathlib.Path(__file__).resolve().parents[1] / "temc_train"
WALLS = ("drivers", "probes", "vectors")
LIBRARY = sorted(PKG.glob("*.py"))
COMMANDS = sorted(p for w in WALLS for p in (PKG / w).glob("*.py") if p.name != "__init__.py")
HELPERS = {"distributed.py"}  # drivers/train.py's process group, not a command


def imported(path: pathlib.Path) -> set:
    """The temc_train modules `path` imports, as dotted names under temc_train."""
    return imports(path.read_text(), list(path.relative_to(PKG).parent.parts))


def imports(source: str, folder: list) -> set:
    """The temc_train modules (and names from them) `source` imports, as dotted names, for a
    module in temc_train/FOLDER..."""
    pkg = ["temc_train"] + folder
    out = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("temc_train")}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg[: len(pkg) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            elif (node.module or "").startswith("temc_train"):
                mod = node.module
            else:
                continue
            out.add(mod)
            out |= {f"{mod}.{a.name}" for a in node.names}
    return out


def test_the_scan_sees_relative_and_absolute_imports():
    assert "temc_train.drivers.train" in imports("from .drivers import train", [])
    assert "temc_train.drivers" in imports("def f():\n    from . import drivers", [])
    assert "temc_train.drivers.ship" in imports("from ..drivers.ship import card", ["probes"])
    assert "temc_train.probes.report" in imports("import temc_train.probes.report", [])
    assert "temc_train.drivers" in imports("from temc_train.drivers import export", [])
    assert not imports("import os\nfrom torch import nn", [])
    assert "temc_train.checkpoint" in imported(PKG / "drivers" / "budget.py")
    assert "temc_train.reconstruct" in imported(PKG / "vectors" / "recon_vectors.py")
    assert "temc_train.probes.probe" in imported(PKG / "probes" / "leak_probe.py")


@pytest.mark.parametrize("path", LIBRARY, ids=lambda p: p.name)
def test_the_library_never_imports_a_wall(path):
    bad = {m for m in imported(path) for w in WALLS if m == f"temc_train.{w}" or m.startswith(f"temc_train.{w}.")}
    assert not bad, f"{path.name} imports {sorted(bad)}"


@pytest.mark.parametrize("path", LIBRARY, ids=lambda p: p.name)
def test_the_library_has_no_entry_points(path):
    assert '__name__ == "__main__"' not in path.read_text(), f"{path.name}: commands live in {WALLS}"


@pytest.mark.parametrize("path", COMMANDS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_module_in_a_wall_is_a_command(path):
    if path.name in HELPERS:
        return
    text = path.read_text()
    assert "def main(" in text and '__name__ == "__main__"' in text, path.name


@pytest.mark.parametrize("path", sorted((PKG / "vectors").glob("*.py")), ids=lambda p: p.name)
def test_vector_writers_import_only_the_library(path):
    bad = {m for m in imported(path) for w in ("drivers", "probes")
           if m == f"temc_train.{w}" or m.startswith(f"temc_train.{w}.")}
    assert not bad, f"{path.name} imports {sorted(bad)}"
