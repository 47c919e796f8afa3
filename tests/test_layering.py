"""The package's layers, checked statically on its import graph: every module under
regrasp_cli/ is parsed with ``ast`` (nothing is imported), and every ``import x`` and
``from x import y`` at any depth (inside functions, ``if TYPE_CHECKING:``, ``try:``)
becomes an edge importer -> imported, relative imports resolved and ``from pkg import
mod`` taken as the module ``pkg.mod``.

Rules:

(a) a module imports only modules of its own layer or lower ones; besides, the validator
    stays independent of the planner (``validate`` imports nothing of ``manip`` but the
    leaf ``manip.modes``) and the viewer of the validator (``show`` never imports
    ``validate``);
(b) no library module (anything but ``commands.*`` and ``cli``) imports ``rich``,
    ``click``, ``regrasp_cli.commands`` or ``regrasp_cli.cli``, but for :data:`ALLOWED`;
(c) every module has a layer, and every entry of :data:`LAYERS` names a module that exists;
(d) a package's ``__init__`` runs whenever any module under it is imported, so it imports
    only what its lowest-layer module may (e.g. ``manip/__init__`` as ``manip.modes``);
(e) every ``regrasp_cli`` import names a module that exists (lazy imports inside
    functions are not exercised by importing the package);
(f) no module imports another's private name (``from m import _x`` or ``m._x``);
(g) no import cycle, imports inside functions included (issue 42);
(h) commands and benchmarks solve and record a task only through :mod:`regrasp_cli.pipeline`
    (issue 42: one pipeline), which the FORBIDDEN entries of ``manip.record`` and
    ``manip.tasks`` say.

``test_checker_*`` run the checker on tiny synthetic sources with known bad edges, so
that the rules cannot pass vacuously.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = "regrasp_cli"

# lowest first; "x.*" is the module x (a package) and everything under it, "x" that module
# alone; the most specific entry wins (so "manip.modes" is L0 inside L4's "manip.*")
LAYERS: tuple[tuple[str, ...], ...] = (
    ("", "errors", "spatial", "examples", "config", "inputs", "store", "parallel", "manip.modes"),  # "": the package __init__
    ("model.*", "grasp.*", "placement.*", "scene", "motion.*"),
    ("roadmap.*",),
    ("trajectory", "replay", "artefacts"),
    ("manip.*", "dexterous.*", "checks", "validate", "validate_inhand"),
    ("show.*", "bench.*", "export", "simulate", "pipeline"),
    ("commands.*", "cli"),
)
LAYER_NAMES = ("L0 core", "L1 model/grasp/scene/motion", "L2 roadmap", "L3 plan format/replay/artefacts",
               "L4 planner/validator", "L5 show/bench/export/simulate/pipeline", "L6 commands/cli")

# (importer, importer may not import this module or anything under it, unless it is one of these)
FORBIDDEN: tuple[tuple[str, str, tuple[str, ...], str], ...] = (
    ("validate", "manip", ("manip.modes",), "the validator is independent of the planner"),
    ("checks", "manip", ("manip.modes",), "the validator is independent of the planner"),
    ("checks", "dexterous", (), "the validator is independent of the planner"),
    ("validate_inhand", "manip", ("manip.modes",), "the validator is independent of the planner"),
    ("validate_inhand", "dexterous", (), "the validator is independent of the planner"),
    ("validate", "dexterous", (), "the validator is independent of the planner"),
    ("show.*", "validate", (), "the viewer replays plans (replay.py) without the validator"),
    ("export", "manip", ("manip.modes",), "the export samples the plan file, not the planner"),
    ("simulate", "manip", ("manip.modes",), "the physics check replays the plan file, not the planner"),
    ("simulate", "validate", (), "the physics check is independent of the validator"),
    ("commands.*", "manip.record", (), "every task is recorded by the one pipeline (pipeline.run_task)"),
    ("bench.*", "manip.record", (), "every task is recorded by the one pipeline (pipeline.run_task)"),
    ("commands.*", "manip.tasks", (), "every task is solved by the one pipeline (pipeline.run_task)"),
)

CLI_MODULES = ("commands.*", "cli")  # the only modules that may print with rich or use click
UI_IMPORTS = ("rich", "click", f"{PKG}.commands", f"{PKG}.cli")

# (library module, imported module) -> why it may
ALLOWED: dict[tuple[str, str], str] = {}  # (importer, imported) -> why; none today


# ------------------------------------------------------------------ the checker


@dataclass(frozen=True)
class Edge:
    importer: str
    imported: str  # a module name (ours resolved to a module of the package when it is one)
    file: str
    line: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}: {self.importer} -> {self.imported}"


def read_sources(root: Path = ROOT) -> dict[str, str]:
    """``{path relative to root (posix): source}`` of every module of the package."""
    return {p.relative_to(root).as_posix(): p.read_text(encoding="utf-8")
            for p in sorted((root / PKG).rglob("*.py")) if "__pycache__" not in p.parts}


def module_of(path: str) -> tuple[str, bool]:
    """Module name of a file path and whether it is a package (an ``__init__``)."""
    parts = path[:-len(".py")].split("/")
    if parts[-1] == "__init__":
        return ".".join(parts[:-1]), True
    return ".".join(parts), False


def modules_of(sources: dict[str, str]) -> dict[str, str]:
    """``{module name: path}``."""
    return {module_of(path)[0]: path for path in sources}


def _absolute(module: str, is_package: bool, level: int, name: str | None) -> str:
    if level == 0:
        return name or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    if level - 1 > len(base) - 1:
        raise ValueError(f"relative import beyond the top of {module}")
    base = base[:len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def edges_of(sources: dict[str, str]) -> list[Edge]:
    """Every import of every module, resolved; ``from pkg import mod`` is the module
    ``pkg.mod`` when that is one of ours, else ``pkg``."""
    known = modules_of(sources)
    out = []
    for path, text in sources.items():
        module, is_package = module_of(path)
        for node in ast.walk(ast.parse(text, filename=path)):
            if isinstance(node, ast.Import):
                out += [Edge(module, a.name, path, node.lineno) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _absolute(module, is_package, node.level, node.module)
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    out.append(Edge(module, sub if sub in known else base, path, node.lineno))
            elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
                  and isinstance(node.args[0].value, str)
                  and (isinstance(node.func, ast.Attribute) and node.func.attr == "import_module"
                       or isinstance(node.func, ast.Name) and node.func.id in ("import_module", "__import__"))):
                out.append(Edge(module, node.args[0].value, path, node.lineno))
    return sorted(out, key=lambda e: (e.file, e.line, e.imported))


def _full(pattern: str) -> tuple[str, bool]:
    """Full module name of a layer entry and whether it covers the modules under it."""
    star = pattern.endswith(".*")
    name = pattern[:-2] if star else pattern
    return (f"{PKG}.{name}" if name else PKG), star


def matches(pattern: str, module: str) -> bool:
    name, star = _full(pattern)
    return module == name or star and module.startswith(name + ".")


def assigned_layer(module: str, layers=LAYERS) -> int | None:
    """The layer of the most specific entry that matches ``module`` (None: no entry)."""
    best = None  # (specificity, layer)
    for k, entries in enumerate(layers):
        for pattern in entries:
            if matches(pattern, module):
                name, star = _full(pattern)
                key = (name.count(".") + (0 if star else 0.5), k)
                best = max(best, key) if best else key
    return None if best is None else best[1]


def ours(module: str) -> bool:
    return module == PKG or module.startswith(PKG + ".")


def layer_violations(sources: dict[str, str], layers=LAYERS, forbidden=FORBIDDEN) -> list[str]:
    """Rule (a): edges to a higher layer, and the FORBIDDEN edges."""
    bad = []
    for e in edges_of(sources):
        if not ours(e.imported):
            continue
        a, b = assigned_layer(e.importer, layers), assigned_layer(e.imported, layers)
        if a is not None and b is not None and b > a:
            bad.append(f"{e}  (layer {a} imports layer {b})")
        for importer, target, except_, why in forbidden:
            if (matches(importer, e.importer) and matches(target + ".*", e.imported)
                    and not any(matches(x, e.imported) for x in except_)):
                bad.append(f"{e}  ({why})")
    return bad


def ui_violations(sources: dict[str, str], allowed=ALLOWED) -> list[str]:
    """Rule (b): library modules importing rich, click or the command layer, but for
    ``allowed``."""
    bad = []
    for e in edges_of(sources):
        if any(matches(p, e.importer) for p in CLI_MODULES) or (e.importer, e.imported) in allowed:
            continue
        if any(e.imported == u or e.imported.startswith(u + ".") for u in UI_IMPORTS):
            bad.append(str(e))
    return bad


def unassigned(sources: dict[str, str], layers=LAYERS) -> list[str]:
    """Rule (c): modules without a layer, and layer entries that match no module."""
    modules = modules_of(sources)
    bad = [f"{path}: {m} has no layer; add it to LAYERS in tests/test_layering.py"
           for m, path in modules.items() if assigned_layer(m, layers) is None]
    bad += [f"LAYERS entry {p!r} (layer {k}) matches no module under {PKG}/; remove or rename it"
            for k, entries in enumerate(layers) for p in entries if not any(matches(p, m) for m in modules)]
    return bad


def init_violations(sources: dict[str, str], layers=LAYERS) -> list[str]:
    """Rule (d): a package ``__init__`` imports nothing above the lowest layer of the
    modules under it (they all run it first)."""
    modules = modules_of(sources)
    bad = []
    for e in edges_of(sources):
        if not ours(e.imported) or not module_of(e.file)[1] or e.importer == PKG:
            continue  # the package's own __init__ is L0 already
        floor = min(assigned_layer(m, layers) for m in modules if m == e.importer or m.startswith(e.importer + "."))
        b = assigned_layer(e.imported, layers)
        if b is not None and b > floor:
            bad.append(f"{e}  (the package's __init__ runs before its layer-{floor} modules; it imports layer {b})")
    return bad


def dangling(sources: dict[str, str]) -> list[str]:
    """Rule (e): imports of regrasp_cli modules that do not exist."""
    known = modules_of(sources)
    return [f"{e}  (no such module)" for e in edges_of(sources) if ours(e.imported) and e.imported not in known]


def private_imports(sources: dict[str, str]) -> list[str]:
    """Rule (f): no module imports another module's private name (``from m import _x``,
    or ``m._x`` of a module imported as ``m``): what two modules share is public."""
    known = modules_of(sources)
    bad = []
    for path, text in sources.items():
        module, is_package = module_of(path)
        aliases = {}  # local name -> our module, for attribute access
        tree = ast.parse(text, filename=path)
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module != "__future__":
                base = _absolute(module, is_package, node.level, node.module)
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    if sub in known:
                        aliases[a.asname or a.name] = sub
                    elif ours(base) and base != module and a.name.startswith("_") and not a.name.startswith("__"):
                        bad.append(f"{path}:{node.lineno}: {module} imports {base}.{a.name}")
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if ours(a.name) and a.asname:
                        aliases[a.asname] = a.name
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases
                    and node.attr.startswith("_") and not node.attr.startswith("__")):
                bad.append(f"{path}:{node.lineno}: {module} uses {aliases[node.value.id]}.{node.attr}")
    return sorted(bad)


def import_cycles(sources: dict[str, str]) -> list[str]:
    """Rule (g): no two modules import each other, directly or through others (imports
    inside functions count: they are a dependency all the same)."""
    import networkx as nx

    known = modules_of(sources)
    g = nx.DiGraph((e.importer, e.imported) for e in edges_of(sources)
                   if e.imported in known and e.importer != e.imported)
    return [" -> ".join(sorted(c)) for c in nx.strongly_connected_components(g) if len(c) > 1]


def report(title: str, lines: list[str]) -> str:
    return f"{title} ({len(lines)}):\n  " + "\n  ".join(lines)


# ------------------------------------------------------------------ the package


@pytest.fixture(scope="module")
def sources() -> dict[str, str]:
    s = read_sources()
    assert f"{PKG}/cli.py" in s and len(s) > 20, sorted(s)
    return s


def test_every_module_has_a_layer(sources):
    bad = unassigned(sources)
    assert not bad, report("modules without a layer, or stale LAYERS entries", bad)


def test_no_module_imports_a_higher_layer(sources):
    bad = layer_violations(sources)
    assert not bad, report("upward or forbidden imports (importer -> imported); layers: "
                           + ", ".join(LAYER_NAMES), bad)


def test_library_modules_do_not_import_rich_click_or_the_command_layer(sources):
    bad = ui_violations(sources)
    assert not bad, report("library modules importing rich/click/commands/cli (importer -> imported)", bad)


def test_no_module_imports_another_s_private_names(sources):
    bad = private_imports(sources)
    assert not bad, report("private names used across modules (make them public, or keep them home)", bad)


def test_no_import_cycles(sources):
    bad = import_cycles(sources)
    assert not bad, report("modules importing each other (strongly connected sets)", bad)


def test_allowed_exceptions_are_still_used(sources):
    """An ALLOWED entry no longer needed is removed, so the list stays the true one."""
    edges = {(e.importer, e.imported) for e in edges_of(sources)}
    stale = [f"{a} -> {b}" for a, b in ALLOWED if (a, b) not in edges]
    assert not stale, report("ALLOWED entries with no such import any more; remove them", stale)


def test_package_inits_import_only_what_their_lowest_module_may(sources):
    bad = init_violations(sources)
    assert not bad, report("package __init__ imports above their lowest module's layer", bad)


def test_every_internal_import_names_an_existing_module(sources):
    bad = dangling(sources)
    assert not bad, report("imports of regrasp_cli modules that do not exist", bad)


# ------------------------------------------------------------------ the checker finds what it should

SYNTHETIC = {
    "regrasp_cli/__init__.py": "",
    "regrasp_cli/spatial.py": "import numpy as np\n",
    "regrasp_cli/scene.py": "from regrasp_cli import spatial\n",
    "regrasp_cli/roadmap/__init__.py": "",
    "regrasp_cli/roadmap/build.py": "from . import compose\nfrom ..scene import load\n",  # relative, downward
    "regrasp_cli/roadmap/compose.py": "def f():\n    from ..validate import check\n",  # relative, nested, upward
    "regrasp_cli/manip/__init__.py": "",
    "regrasp_cli/manip/modes.py": "",
    "regrasp_cli/manip/solve.py": "from regrasp_cli.manip import modes\n",
    "regrasp_cli/validate.py": ("from regrasp_cli.manip.modes import Kind\n"
                                "def v():\n    if True:\n        from regrasp_cli.manip import solve\n"),
    "regrasp_cli/show/__init__.py": "",
    "regrasp_cli/show/html.py": "import regrasp_cli.validate\n",
    "regrasp_cli/bench/__init__.py": "",
    "regrasp_cli/bench/report.py": "def p(c):\n    from rich.table import Table\n",
    "regrasp_cli/bench/runner.py": "from regrasp_cli.commands.report import CliBuilder\nimport click\n",
    "regrasp_cli/commands/__init__.py": "",
    "regrasp_cli/commands/report.py": "from rich.console import Console\nfrom regrasp_cli.bench import runner\n",
    "regrasp_cli/cli.py": "import click\nfrom regrasp_cli.commands import report\n",
}


def test_checker_resolves_relative_nested_and_from_imports():
    edges = {(e.importer, e.imported, e.line) for e in edges_of(SYNTHETIC)}
    assert ("regrasp_cli.roadmap.build", "regrasp_cli.roadmap.compose", 1) in edges
    assert ("regrasp_cli.roadmap.build", "regrasp_cli.scene", 2) in edges
    assert ("regrasp_cli.roadmap.compose", "regrasp_cli.validate", 2) in edges
    assert ("regrasp_cli.validate", "regrasp_cli.manip.solve", 4) in edges
    assert ("regrasp_cli.scene", "regrasp_cli.spatial", 1) in edges


def test_checker_reports_upward_and_forbidden_edges():
    bad = "\n".join(layer_violations(SYNTHETIC))
    assert "regrasp_cli/roadmap/compose.py:2: regrasp_cli.roadmap.compose -> regrasp_cli.validate" in bad  # 2 -> 4
    assert "regrasp_cli/bench/runner.py:1: regrasp_cli.bench.runner -> regrasp_cli.commands.report" in bad  # 5 -> 6
    assert "regrasp_cli.validate -> regrasp_cli.manip.solve" in bad  # same layer, but forbidden
    assert "regrasp_cli.show.html -> regrasp_cli.validate" in bad  # a lower layer, but forbidden
    assert "regrasp_cli.validate -> regrasp_cli.manip.modes" not in bad  # the leaf is allowed
    assert "regrasp_cli.manip.solve -> regrasp_cli.manip.modes" not in bad
    assert "regrasp_cli.commands.report -> regrasp_cli.bench.runner" not in bad  # downward
    assert "regrasp_cli.roadmap.build" not in bad
    assert len(layer_violations(SYNTHETIC)) == 4


def test_checker_reports_rich_and_click_in_library_modules_but_for_allowed_ones():
    bad = ui_violations(SYNTHETIC, allowed={})
    assert bad == ["regrasp_cli/bench/report.py:2: regrasp_cli.bench.report -> rich.table",
                   "regrasp_cli/bench/runner.py:1: regrasp_cli.bench.runner -> regrasp_cli.commands.report",
                   "regrasp_cli/bench/runner.py:2: regrasp_cli.bench.runner -> click"]
    assert len(ui_violations(SYNTHETIC, allowed={("regrasp_cli.bench.report", "rich.table"): "why"})) == 2


def test_checker_reports_modules_without_a_layer_and_stale_entries():
    extra = dict(SYNTHETIC, **{"regrasp_cli/newthing.py": ""})
    bad = "\n".join(unassigned(extra))
    assert "regrasp_cli.newthing has no layer; add it to LAYERS" in bad
    assert "'motion.*'" in bad  # an entry matching none of the synthetic modules
    assert assigned_layer("regrasp_cli.manip.modes") == 0 and assigned_layer("regrasp_cli.manip") == 4
    assert assigned_layer("regrasp_cli.manip.tasks.handover") == 4 and assigned_layer("regrasp_cli") == 0


def test_checker_reports_a_package_init_importing_above_its_lowest_module():
    bad = init_violations(dict(SYNTHETIC, **{"regrasp_cli/manip/__init__.py": "from .solve import x\n"}))
    assert bad and "regrasp_cli.manip -> regrasp_cli.manip.solve" in bad[0]
    assert not init_violations(SYNTHETIC)


def test_checker_reports_imports_of_missing_modules():
    bad = dangling(dict(SYNTHETIC, **{"regrasp_cli/scene.py": "from regrasp_cli.plan.command import x\n"}))
    assert bad == ["regrasp_cli/scene.py:1: regrasp_cli.scene -> regrasp_cli.plan.command  (no such module)"]


def test_checker_reports_private_names_across_modules():
    extra = dict(SYNTHETIC, **{
        "regrasp_cli/placement/a.py": "from regrasp_cli.placement.b import _helper, public\nfrom . import b as bee\n"
                                      "def f():\n    return bee._other(), _mine()\ndef _mine():\n    pass\n",
        "regrasp_cli/placement/b.py": "def _helper():\n    pass\n",
        "regrasp_cli/placement/__init__.py": ""})
    bad = private_imports(extra)
    assert bad == ["regrasp_cli/placement/a.py:1: regrasp_cli.placement.a imports regrasp_cli.placement.b._helper",
                   "regrasp_cli/placement/a.py:4: regrasp_cli.placement.a uses regrasp_cli.placement.b._other"]
    assert not private_imports(SYNTHETIC)


def test_checker_reports_import_cycles_through_function_level_imports():
    extra = dict(SYNTHETIC, **{
        "regrasp_cli/placement/a.py": "from regrasp_cli.placement import b\n",
        "regrasp_cli/placement/b.py": "def f():\n    from regrasp_cli.placement.c import g\n",
        "regrasp_cli/placement/c.py": "import regrasp_cli.placement.a\n",
        "regrasp_cli/placement/__init__.py": ""})
    cycles = import_cycles(extra)
    assert "regrasp_cli.placement.a -> regrasp_cli.placement.b -> regrasp_cli.placement.c" in cycles
    assert not any("placement" in c for c in import_cycles(SYNTHETIC))
