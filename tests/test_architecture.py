"""One-way dependencies: rrbc_viz -> rrbc_core; the core never imports viser (or the app).

The `rrbc` command lives in rrbc_core/cli.py; only its `view` subcommand imports rrbc_viz, lazily, when run."""

import subprocess
import sys

import pytest

from tests.paths import ROOT

CORE = ROOT / "rrbc_core"


def test_importing_every_core_module_loads_neither_viser_nor_the_app():
    modules = sorted(
        ".".join(p.relative_to(CORE).with_suffix("").parts)
        for p in CORE.rglob("*.py")
        if p.stem != "__init__" and p.parent.name != "data"
    )
    code = (
        "import importlib, sys\n"
        f"for m in {modules!r}: importlib.import_module('rrbc_core.' + m)\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('viser', 'rrbc_viz'))\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "", f"core imported: {out.stdout.strip()}"
    assert "cli" in modules and "session.explorer" in modules  # the test covers the modules that matter


def test_rrbc_correct_runs_without_loading_the_app(tmp_path):
    example = CORE / "data" / "example_measurements.csv"
    code = (
        "import sys\nfrom rrbc_core.cli import main\n"
        f"rc = main(['correct', {str(example)!r}, '--json'])\n"
        "bad = [m for m in sys.modules if m.split('.')[0] in ('viser', 'rrbc_viz')]\n"
        "sys.stderr.write('LOADED:' + ','.join(bad))\nsys.exit(rc)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stderr.strip().endswith("LOADED:")


def test_every_document_the_code_cites_is_in_the_repository():
    """References in code, scenes and docs (docs/…, scenes/…, docs/theory.md §n) resolve inside the repository, and
    nothing points at material outside it."""
    import re

    sources = [
        p
        for base in ("rrbc_core", "rrbc_viz", "scripts", "benchmarks", "scenes", "docs")
        for p in (ROOT / base).rglob("*")
        if p.suffix in (".py", ".md", ".toml")
    ] + [ROOT / "README.md"]
    theory = (ROOT / "docs" / "theory.md").read_text()
    sections = set(re.findall(r"§(\d+(?:\.\d+)?)", theory.split("\n## ", 1)[1]))
    missing, outside = [], []
    for src in sources:
        text = src.read_text()
        for ref in re.findall(r"(?<![\w/.])((?:docs|scenes)/[\w/.-]+\.(?:md|toml|png|json))", text):
            if not (ROOT / ref).exists():
                missing.append(f"{src.relative_to(ROOT)}: {ref}")
        for sec in re.findall(r"docs/theory\.md (§[\d.]+\d)", text):
            if sec[1:] not in sections:
                missing.append(f"{src.relative_to(ROOT)}: theory {sec}")
        if re.search(r"shared/(spec|notes|domain|reference)|theory notes", text):
            outside.append(str(src.relative_to(ROOT)))
    assert not missing, missing
    assert not outside, outside


def _import_graph(package: str, type_only: bool = True, lazy: bool = True) -> dict:
    """Module -> modules of `package` it imports: at module level, inside `if TYPE_CHECKING:` when type_only, and
    inside functions and methods (the lazy imports) when lazy."""
    import ast

    def name(p):
        parts = list(p.relative_to(ROOT).with_suffix("").parts)
        return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)

    def imports(tree):
        if lazy:
            yield from ast.walk(tree)
            return
        pending = list(tree.body)
        for node in pending:
            if isinstance(node, ast.If) and (type_only or "TYPE_CHECKING" not in ast.dump(node.test)):
                pending.extend(node.body)
            yield node

    mods = {name(p): p for p in (ROOT / package).rglob("*.py")}
    graph = {m: set() for m in mods}
    for m, path in mods.items():
        for node in imports(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                base = m.split(".") if path.name == "__init__.py" else m.split(".")[:-1]
                target = (
                    ".".join(base[: len(base) - node.level + 1] + [node.module or ""]).strip(".")
                    if node.level
                    else node.module
                )
                subs = {f"{target}.{a.name}" for a in node.names} & set(mods)
                others = [a for a in node.names if f"{target}.{a.name}" not in mods]
                # `from pkg import sub` inside pkg runs pkg/__init__ first: an edge to the package itself, so a
                # package whose __init__ imports the importer is a cycle (the root packages' lazy __init__ excepted)
                own_package = target in mods and "." in target and m.startswith(target + ".")
                graph[m] |= (subs | ({target} if (others or own_package) and target in mods else set())) - {m}
            elif isinstance(node, ast.Import):
                graph[m] |= {a.name for a in node.names if a.name in mods} - {m}
    return graph


def _cycles(graph: dict) -> list:
    found, state, stack = [], {}, []

    def visit(u):
        state[u] = 1
        stack.append(u)
        for v in sorted(graph[u]):
            if state.get(v) == 1:
                found.append(stack[stack.index(v) :] + [v])
            elif v not in state:
                visit(v)
        stack.pop()
        state[u] = 2

    for u in sorted(graph):
        if u not in state:
            visit(u)
    return found


def test_no_import_cycles():
    """The modules of each package import each other in one direction: module-level, type-only and lazy imports
    (inside functions) alike."""
    assert _cycles(_import_graph("rrbc_core")) == []
    assert _cycles(_import_graph("rrbc_viz")) == []


def test_the_import_checks_see_lazy_and_type_only_imports():
    """The graph the layer and cycle tests read includes an import inside a function (the command's lazy imports)
    and one under `if TYPE_CHECKING:` (the controllers' context)."""
    core = _import_graph("rrbc_core")
    assert "rrbc_core.cli_reproduce" in core["rrbc_core.cli"]  # imported inside the subcommand that runs it
    assert "rrbc_core.cli_reproduce" not in _import_graph("rrbc_core", type_only=False, lazy=False)["rrbc_core.cli"]
    viz = _import_graph("rrbc_viz")
    assert "rrbc_viz.context" in viz["rrbc_viz.controllers.evaluate"]
    assert (
        "rrbc_viz.context"
        not in _import_graph("rrbc_viz", type_only=False, lazy=False)["rrbc_viz.controllers.evaluate"]
    )


def _layer_table(package: str) -> list:
    """The layer table of `package` in docs/architecture.md: [(layer, entries, row text)], top layer first; an entry
    is a module (`cli`, `__init__`) or a subpackage (`runtime/`)."""
    import re

    text = (ROOT / "docs" / "architecture.md").read_text()
    section = text.split(f"## The layers of `{package}`", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or cells[0] in ("layer", "---"):
            continue
        rows.append((cells[0], re.findall(r"`([^`]+)`", cells[1]), line))
    assert len(rows) >= 5, f"no layer table for {package} in docs/architecture.md"
    return rows


def _layer_of(package: str, module: str, rows: list) -> list:
    """Indices of the rows whose entries hold `module` (a dotted name)."""
    found = []
    for i, (_, entries, _) in enumerate(rows):
        for entry in entries:
            dotted = package if entry == "__init__" else f"{package}.{entry.rstrip('/').replace('/', '.')}"
            if module == dotted or (entry.endswith("/") and module.startswith(dotted + ".")):
                found.append(i)
    return found


@pytest.mark.parametrize("package", ["rrbc_core", "rrbc_viz"])
def test_every_module_is_placed_in_one_documented_layer(package):
    import re

    rows = _layer_table(package)
    graph = _import_graph(package)
    unplaced, twice, unnamed = [], [], []
    for module in sorted(graph):
        found = _layer_of(package, module, rows)
        if not found:
            unplaced.append(module)
        elif len(set(found)) > 1:
            twice.append(module)
        elif module != package:
            stem = module.rsplit(".", 1)[1]
            if not re.search(rf"`[^`]*\b{stem}\b[^`]*`", rows[found[0]][2]):
                unnamed.append(module)
    assert not unplaced, f"modules in no layer of docs/architecture.md: {unplaced}"
    assert not twice, f"modules in two layers: {twice}"
    assert not unnamed, f"modules their layer's row does not name: {unnamed}"


@pytest.mark.parametrize("package", ["rrbc_core", "rrbc_viz"])
def test_imports_follow_the_documented_layer_order(package):
    """A module imports only from its own layer and the layers above it in docs/architecture.md (lazy and type-only
    imports included)."""
    rows = _layer_table(package)
    graph = _import_graph(package)
    upward = []
    for module, deps in sorted(graph.items()):
        mine = _layer_of(package, module, rows)[0]
        for dep in sorted(deps):
            if dep == package:  # the package's __init__ (lazy public names) is imported by nobody inside
                upward.append(f"{module} -> {dep}")
                continue
            theirs = _layer_of(package, dep, rows)[0]
            if theirs > mine:
                upward.append(f"{module} ({rows[mine][0]}) -> {dep} ({rows[theirs][0]})")
    assert not upward, upward


def test_the_core_imports_the_app_only_where_rrbc_view_starts_it():
    import ast

    found = []
    for path in sorted(CORE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = (
                [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else []
            )
            found += [f"{path.relative_to(ROOT)}:{node.lineno} {n}" for n in names if n.split(".")[0] == "rrbc_viz"]
    assert len(found) == 1 and found[0].startswith("rrbc_core/cli.py:") and found[0].endswith(" rrbc_viz.serve")


def test_app_panels_do_not_import_the_app():
    graph = _import_graph("rrbc_viz", type_only=True)
    for panel in ("rrbc_viz.controls", "rrbc_viz.planning_panel", "rrbc_viz.diagnosis_panel", "rrbc_viz.actions"):
        assert "rrbc_viz.app" not in graph[panel], panel


def _resolves(dotted: str) -> bool:
    """True if `dotted` (rrbc_core.… or rrbc_viz.…) names a module, or an attribute or dataclass field in one."""
    import importlib

    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ModuleNotFoundError:
            continue
        for attr in parts[k:]:
            if hasattr(obj, attr):
                obj = getattr(obj, attr)
            elif isinstance(obj, type) and (
                attr in getattr(obj, "__dataclass_fields__", {}) or attr in getattr(obj, "__annotations__", {})
            ):
                return True  # a field of a (data)class: an instance attribute
            else:
                return False
        return True
    return False


def test_every_dotted_name_and_source_path_in_the_code_and_docs_resolves():
    """`rrbc_core.session.explorer.ExplorerSession.move`, `rrbc_viz.serve.serve`, `rrbc_core/analysis/planning.py`:
    every such name in docstrings, comments, docs, scripts and tests points at something that exists."""
    import re

    sources = [
        p
        for base in ("rrbc_core", "rrbc_viz", "scripts", "benchmarks", "docs", "tests", "examples", "scenes", ".ci")
        if (ROOT / base).exists()
        for p in (ROOT / base).rglob("*")
        if p.suffix in (".py", ".md", ".sh", ".toml") or p.name == "run"
    ] + [ROOT / "README.md"]
    stale = []
    for src in sources:
        text = src.read_text()
        for name in set(re.findall(r"(?<![\w./])(rrbc_(?:core|viz)(?:\.[A-Za-z_]\w*)+)", text)):
            if not _resolves(name):
                stale.append(f"{src.relative_to(ROOT)}: {name}")
        for path in set(re.findall(r"(?<![\w./])(rrbc_(?:core|viz)/[\w/]+\.(?:py|csv))", text)):
            if not (ROOT / path).exists():
                stale.append(f"{src.relative_to(ROOT)}: {path}")
        # test files, scripts, benchmarks and examples named by path (a test file that moved leaves these behind)
        for path in set(re.findall(r"(?<![\w./])((?:tests|scripts|benchmarks|examples)/[\w/.-]+\.(?:py|sh))", text)):
            if not (ROOT / path).exists():
                stale.append(f"{src.relative_to(ROOT)}: {path}")
    assert not stale, stale
    assert _resolves("rrbc_core.session.explorer.ExplorerSession.move") and not _resolves("rrbc_core" + ".explorer")
