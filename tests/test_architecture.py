"""The package's import rules (docs/architecture.md), checked on the source.

Fast: every module under `jaxgeo/` is parsed with `ast`, nothing is imported or
compiled. Every `import` counts, wherever it stands (module level, inside a
function, under `if TYPE_CHECKING:`), except that the cycle check skips
`TYPE_CHECKING` imports, which never run.

1. No cycles among the modules' imports.
2. The layering: a module imports only modules of its own layer or of the layers
   below it (`LAYERS`; every module must be placed in one).
3. No module uses another module's private names: neither `from .x import _y` nor
   `x._y` on an imported jaxgeo module. Private *modules* (`jaxgeo._sleeve`) may be
   imported; their public names are their interface.

Importing a submodule (`jaxgeo.cutting.cut`) runs its package's `__init__`
(`jaxgeo.cutting`) first: for rule 2 a module outside a package that imports one
of its submodules imports the package too.

Rule 1 has no exceptions. `ALLOWED_PRIVATE` lists what breaks rule 3 (today
nothing), each entry with the reason it is not a rename; an entry that no longer
occurs fails the test, so the list only shrinks.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "jaxgeo"

# --------------------------------------------------------------------------- layers
#: Layer name -> (its modules, the layers directly below it). A module may import
#: modules of its own layer and of every layer reachable downwards. Module names
#: are relative to `jaxgeo` ("" is the package itself). Keep in step with the
#: drawing in docs/architecture.md.
LAYERS: dict[str, tuple[set[str], set[str]]] = {
    # small helpers with no jaxgeo imports but each other
    "foundation": (
        {
            "_errors",
            "_numerics",
            "_precision",
            "_cache",
            "_linear",
            "_phong",
            "_stacklevel",
        },
        set(),
    ),
    # the Mesh pytree, its validation and host-side tables, loading, repair,
    # built-in surfaces
    "mesh": (
        {
            "mesh",
            "_mesh_checks",
            "_merge",
            "loading",
            "repair",
            "_fans",
            "_landmarks",
            "_cuts",
            "_curvature",
            "_padding",
            "surfaces",
            "_grids",
            "formfinding",  # numpy form finding behind surfaces.four_point_sail
            "data",
            "data.__main__",
        },
        {"foundation"},
    ),
    # places on the surface and results: SurfacePoint, Path, argument checks,
    # boundary loops
    "surface": ({"locate", "path", "_checks", "boundary"}, {"mesh"}),
    # the paper's method: normals (eq. 8-10), System (16), the laser trace, replay
    "laser": ({"normals", "projection", "trace", "replay"}, {"surface"}),
    # the exact polyhedral engine (a sibling of the laser: neither imports the other)
    "exact": ({"_sleeve", "_starts", "exact"}, {"surface"}),
    # geodesics of the Phong surface (uses the laser layer's normals)
    "smooth": (
        {
            "smooth",
            "_smooth_strip",
            "_smooth_newton",
            "_smooth_unfold",
            "_smooth_repair",
        },
        {"laser"},
    ),
    # the three methods as eqx.Modules
    "methods": ({"methods"}, {"laser", "exact", "smooth"}),
    # the one pipeline: shortest_path, path_length, solve
    "geodesic": ({"geodesic"}, {"methods"}),
    # many paths: shortest_paths
    "batch": ({"batch"}, {"geodesic"}),
    # what is built on geodesics: validation, seams, flattening, cutting, export
    "applications": (
        {
            "validation",
            "validation.analytic",
            "validation.suites",
            "validation.references",
            "validation.report",
            "io",
            "seams",
            "pattern",
            "export",
            "cutting",
            "cutting._least_strain",
            "cutting.compare",
            "cutting.compensate",
            "cutting.cut",
            "cutting.export",
            "cutting.fabricate",
            "cutting.flatten",
            "cutting.formfinding",
            "cutting.layout",
            "cutting.material",
            "cutting.objective",
            "cutting.optimise",
            "cutting.plots",
            "cutting.reassembly",
            "cutting.seam_width",
        },
        {"batch"},
    ),
    # front ends: the `jaxgeo` command (one module per subcommand) and the package
    "front": (
        {
            "cli",
            "cli.__main__",
            "cli.common",
            "cli.path",
            "cli.paths",
            "cli.surface",
            "cli.validate",
            "cli.pattern",
            "",
        },
        {"applications"},
    ),
}

# ---------------------------------------------------------------- the to-do lists
#: (importer, imported module, private name) uses, with the reason.
ALLOWED_PRIVATE: dict[tuple[str, str, str], str] = {}


# ------------------------------------------------------------------- the parsing
def _modules() -> dict[str, Path]:
    out = {}
    for p in sorted(PACKAGE.rglob("*.py")):
        parts = list(p.relative_to(PACKAGE).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


MODULES = _modules()


def _resolve(importer: str, is_package: bool, level: int, module: str | None) -> str:
    """The module name (relative to jaxgeo) an `ImportFrom` names."""
    if level == 0:
        assert module is not None
        base = module.split(".")[1:]  # drop "jaxgeo"
    else:
        base = importer.split(".") if importer else []
        if not is_package:
            base = base[:-1]
        base = base[: len(base) - (level - 1)]
        base = base + (module.split(".") if module else [])
    return ".".join(x for x in base if x)


def _type_checking_nodes(tree: ast.Module) -> set[int]:
    """ids of the nodes inside `if TYPE_CHECKING:` blocks."""
    inside = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for stmt in node.body:
                inside.update(id(n) for n in ast.walk(stmt))
    return inside


class Use:
    """One import edge or private-name use, with where it is."""

    def __init__(self, importer, imported, name, line, type_only):
        self.importer, self.imported, self.name = importer, imported, name
        self.line, self.type_only = line, type_only

    def __repr__(self):
        what = f"{self.imported}.{self.name}" if self.name else self.imported
        where = MODULES[self.importer].relative_to(PACKAGE)
        return f"jaxgeo/{where}:{self.line} {what}"


def _scan(importer: str, source: str | None = None) -> tuple[list[Use], list[Use]]:
    """(import edges, private-name uses) of one module, read from its file or
    from `source` (a stand-in text, for the scanner's own test)."""
    path = MODULES[importer]
    text = path.read_text() if source is None else source
    tree = ast.parse(text, filename=str(path))
    is_package = path.name == "__init__.py"
    tc = _type_checking_nodes(tree)
    edges, private = [], []
    aliases: dict[str, str] = {}  # local name -> jaxgeo module it is bound to
    for node in ast.walk(tree):
        type_only = id(node) in tc
        if isinstance(node, ast.ImportFrom):
            if not (node.level or (node.module or "").split(".")[0] == "jaxgeo"):
                continue
            target = _resolve(importer, is_package, node.level, node.module)
            for a in node.names:
                sub = f"{target}.{a.name}" if target else a.name
                if sub in MODULES:  # `from . import _sleeve`: a module
                    edges.append(Use(importer, sub, "", node.lineno, type_only))
                    aliases[a.asname or a.name] = sub
                    continue
                edges.append(Use(importer, target, "", node.lineno, type_only))
                if a.name.startswith("_") and not a.name.startswith("__"):
                    private.append(Use(importer, target, a.name, node.lineno, False))
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] != "jaxgeo":
                    continue
                target = ".".join(a.name.split(".")[1:])
                edges.append(Use(importer, target, "", node.lineno, type_only))
                if a.asname:
                    aliases[a.asname] = target
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in aliases
            and node.attr.startswith("_")
            and not node.attr.startswith("__")
        ):
            target = aliases[node.value.id]
            if f"{target}.{node.attr}" not in MODULES:
                private.append(Use(importer, target, node.attr, node.lineno, False))
    return edges, private


SCANS = {m: _scan(m) for m in MODULES}
EDGES = [e for m in MODULES for e in SCANS[m][0] if e.imported != e.importer]


def _layer_of() -> dict[str, str]:
    out = {}
    for layer, (mods, _) in LAYERS.items():
        for m in mods:
            assert m not in out, f"{m!r} is in two layers"
            out[m] = layer
    return out


def _reachable(layer: str) -> set[str]:
    seen, todo = {layer}, [layer]
    while todo:
        for below in LAYERS[todo.pop()][1]:
            if below not in seen:
                seen.add(below)
                todo.append(below)
    return seen


# --------------------------------------------------------------------- the tests
def test_every_module_has_a_layer():
    layer = _layer_of()
    missing = sorted(set(MODULES) - set(layer))
    assert not missing, f"place these modules in test_architecture.LAYERS: {missing}"
    stale = sorted(set(layer) - set(MODULES))
    assert not stale, f"LAYERS names modules that do not exist: {stale}"


def test_scanner_sees_known_imports():
    """The parser itself: edges and private uses it must find (a scanner that
    found nothing would pass every rule)."""
    pairs = {(e.importer, e.imported) for e in EDGES}
    assert ("exact", "_sleeve") in pairs  # `from . import _sleeve`
    assert ("methods", "smooth") in pairs  # an import inside a function
    assert ("cutting.objective", "boundary") in pairs  # `from ..boundary import`
    assert ("validation.report", "validation.references") in pairs  # `from . import`
    assert ("", "geodesic") in pairs  # the package's re-exports
    # no module uses another's private names today: the two forms on a stand-in
    source = "from .mesh import _edges\nfrom . import _sleeve\n_sleeve._cross(a, b)\n"
    private = {(u.importer, u.imported, u.name) for u in _scan("exact", source)[1]}
    assert private == {("exact", "mesh", "_edges"), ("exact", "_sleeve", "_cross")}


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """One cycle per strongly connected component of more than one module
    (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    graph: dict[str, set[str]] = {}
    for e in EDGES:
        if not e.type_only:
            graph.setdefault(e.importer, set()).add(e.imported)
    assert not _cycles(graph), f"import cycles: {_cycles(graph)}"


def test_cycle_finder_sees_a_cycle():
    """The cycle check itself (a finder that found nothing would always pass)."""
    graph = {"surfaces": {"formfinding"}, "formfinding": {"surfaces", "_errors"}}
    assert _cycles(graph) == [["formfinding", "surfaces"]]
    assert _cycles({"surfaces": {"formfinding"}, "formfinding": {"_grids"}}) == []


def _packages_run(importer: str, imported: str) -> list[str]:
    """The packages whose `__init__` importing `imported` runs, that `importer`
    is not inside of (`cutting` for `cutting.cut`, imported from `surfaces`)."""
    parts = imported.split(".")
    outer = [".".join(parts[:k]) for k in range(1, len(parts))]
    return [p for p in outer if not (importer + ".").startswith(p + ".")]


def test_layering():
    layer = _layer_of()
    bad = [
        f"{e!r}: layer {layer[e.importer]!r} imports layer {layer[m]!r}"
        for e in EDGES
        for m in [e.imported, *_packages_run(e.importer, e.imported)]
        if layer[m] not in _reachable(layer[e.importer])
    ]
    assert not bad, "imports upward:\n" + "\n".join(bad)
    # the old sail import: `cutting.formfinding` from `surfaces` runs `cutting`
    assert _packages_run("surfaces", "cutting.formfinding") == ["cutting"]
    assert _packages_run("cutting.cut", "cutting.layout") == []


def test_layers_form_a_hierarchy():
    for name, (_, below) in LAYERS.items():
        assert below <= set(LAYERS), (name, below)
        for b in below:
            assert name not in _reachable(b), f"layers {name!r} and {b!r} form a cycle"


def test_no_private_names_across_modules():
    uses = [u for m in MODULES for u in SCANS[m][1]]
    bad = [u for u in uses if (u.importer, u.imported, u.name) not in ALLOWED_PRIVATE]
    assert not bad, "private names used from another module:\n" + "\n".join(
        map(repr, bad)
    )
    found = {(u.importer, u.imported, u.name) for u in uses}
    stale = sorted(set(ALLOWED_PRIVATE) - found)
    assert not stale, f"remove from ALLOWED_PRIVATE, no longer used: {stale}"
