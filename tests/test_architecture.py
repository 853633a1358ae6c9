"""Imports run one way: every import in ``abs/`` goes down the layer order of docs/architecture.md.

The order is read from the table in docs/architecture.md (between its ``layers:`` markers), so the
document and the check cannot disagree. Every ``import`` and ``from ... import`` in every module is
checked, the ones inside functions included: a lazy import defers a dependency but does not remove
it, and lazy imports are how the old loop (io, scene, brdf, render, report, metrics) hid.
Packages listed in the table but absent from the tree (``model`` until it lands) are fine.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "abs"
DOC = ROOT / "docs" / "architecture.md"
PICTURE = ROOT / "docs" / "architecture.svg"


def read_layers(text: str) -> dict[str, int]:
    """``{package: layer}`` from the table between the ``layers:`` markers (packages in the
    second column, in backticks)."""
    start = text.index("<!-- layers:")
    end = text.index("<!-- layers: end -->")
    layers: dict[str, int] = {}
    for line in text[start:end].splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 2 or not cells[0].isdigit():
            continue
        for name in re.findall(r"`([A-Za-z_][A-Za-z0-9_]*)`", cells[1]):
            assert name not in layers, f"docs/architecture.md lists {name} twice"
            layers[name] = int(cells[0])
    return layers


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def unit(module: str) -> str:
    """The entry of the layer table a module belongs to: the package (or module) directly under
    ``abs``, or ``abs`` itself for ``abs/__init__.py``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "abs"


def imported_modules(path: Path, module: str) -> list[tuple[int, str]]:
    """``(line, module)`` for every abs module an import statement in ``path`` names."""
    is_package = path.name == "__init__.py"
    package = module if is_package else module.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against this module's package
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            # ``from abs import report`` imports the module abs.report, not the package abs.
            targets = [f"abs.{alias.name}" for alias in node.names] if source == "abs" else [source]
        else:
            continue
        found += [(node.lineno, t) for t in targets if t == "abs" or t.startswith("abs.")]
    return found


def edges() -> list[tuple[str, int, str, str]]:
    """``(file, line, importer unit, imported unit)`` for every import between two units."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = module_name(path)
        for line, target in imported_modules(path, module):
            if unit(target) != unit(module):
                out.append((str(path.relative_to(ROOT)), line, unit(module), unit(target)))
    return out


def test_every_import_runs_down_the_layers():
    layers = read_layers(DOC.read_text(encoding="utf-8"))
    present = {unit(module_name(p)) for p in PACKAGE.rglob("*.py")}
    unplaced = sorted(present - set(layers))
    assert not unplaced, f"not in the layer table of docs/architecture.md: {unplaced}"
    wrong = [f"{file}:{line}: {a} (layer {layers[a]}) imports {b} (layer {layers[b]})"
             for file, line, a, b in edges() if layers[b] >= layers[a]]
    assert not wrong, "imports against the layer order of docs/architecture.md:\n" + "\n".join(wrong)


def test_the_check_sees_lazy_relative_and_from_abs_imports(tmp_path):
    """The walker finds imports inside functions, relative imports and ``from abs import x``."""
    pkg = tmp_path / "abs" / "io"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    source = pkg / "thing.py"
    source.write_text("def f():\n    from abs.report import figures\n\n"
                      "from ..scene import load\nfrom abs import metrics\nimport numpy\n")
    module = "abs.io.thing"
    assert sorted(imported_modules(source, module)) == [(2, "abs.report"), (4, "abs.scene"), (5, "abs.metrics")]
    assert unit("abs.report.figures") == "report" and unit("abs") == "abs"


def test_the_table_orders_the_known_loop():
    """The packages of the old import loop are placed, in the order their imports now follow."""
    layers = read_layers(DOC.read_text(encoding="utf-8"))
    assert layers["errors"] == 0
    assert layers["io"] < layers["brdf"] < layers["scene"] < layers["render"] < layers["fitting"]
    assert layers["colour"] < layers["metrics"] < layers["report"] < layers["runs"]
    assert layers["render"] < layers["model"] < min(layers["fitting"], layers["sampling"], layers["diagnosis"])


def test_the_picture_shows_every_package_of_the_table():
    """docs/architecture.svg is drawn from the table (docs/architecture_picture.py): a package
    added to the table without redrawing it is missing from the picture."""
    layers = read_layers(DOC.read_text(encoding="utf-8"))
    shown = set(re.findall(r">([A-Za-z_][A-Za-z0-9_]*)</text>", PICTURE.read_text(encoding="utf-8")))
    missing = sorted(set(layers) - shown)
    assert not missing, f"docs/architecture.svg lacks {missing}: run python docs/architecture_picture.py"


def _top_level_imports(path: Path) -> set[str]:
    """Every imported module name in ``path`` (absolute imports only, functions included)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            names.add(node.module)
            if node.module == "abs":
                names |= {f"abs.{alias.name}" for alias in node.names}
    return names


def test_rig_builds_on_abs_and_only_abs_rig_imports_it():
    """rig/ sits outside abs/, above every layer but cli (docs/architecture.md, "Outside abs/"):
    it imports no abs.cli, and of abs/ only abs/cli/rig.py imports it."""
    rig = ROOT / "rig"
    up = [f"{p.relative_to(ROOT)}: {name}" for p in sorted(rig.rglob("*.py"))
          for name in _top_level_imports(p) if name == "abs.cli" or name.startswith("abs.cli.")]
    assert not up, f"rig/ imports the command line: {up}"
    down = [str(p.relative_to(ROOT)) for p in sorted(PACKAGE.rglob("*.py"))
            if any(n == "rig" or n.startswith("rig.") for n in _top_level_imports(p))]
    assert down in ([], ["abs/cli/rig.py"]), f"only abs/cli/rig.py may import rig: {down}"
