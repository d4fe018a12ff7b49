"""One-way dependencies: rrbc_viz -> rrbc_core; the core never imports viser (or the app).

The `rrbc` command lives in rrbc_core/cli.py; only its `view` subcommand imports rrbc_viz, lazily, when run."""

import subprocess
import sys

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


def _import_graph(package: str, type_only: bool) -> dict:
    """Module -> modules of `package` it imports at module level (inside `if TYPE_CHECKING:` too when type_only)."""
    import ast

    def name(p):
        parts = list(p.relative_to(ROOT).with_suffix("").parts)
        return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)

    mods = {name(p): p for p in (ROOT / package).rglob("*.py") if "data" not in p.parts}
    graph = {m: set() for m in mods}
    for m, path in mods.items():
        pending = list(ast.parse(path.read_text()).body)
        for node in pending:
            if isinstance(node, ast.If) and (type_only or "TYPE_CHECKING" not in ast.dump(node.test)):
                pending.extend(node.body)
            if isinstance(node, ast.ImportFrom):
                base = m.split(".") if path.name == "__init__.py" else m.split(".")[:-1]
                target = (
                    ".".join(base[: len(base) - node.level + 1] + [node.module or ""]).strip(".")
                    if node.level
                    else node.module
                )
                subs = {f"{target}.{a.name}" for a in node.names} & set(mods)
                others = [a for a in node.names if f"{target}.{a.name}" not in mods]
                graph[m] |= (subs | ({target} if others and target in mods else set())) - {m}
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
    """The core's modules import each other in one direction (module level; imports inside functions are the
    deliberate lazy ones); the app's modules too, type-only imports included."""
    assert _cycles(_import_graph("rrbc_core", type_only=False)) == []
    assert _cycles(_import_graph("rrbc_viz", type_only=True)) == []


def test_app_panels_do_not_import_the_app():
    graph = _import_graph("rrbc_viz", type_only=True)
    for panel in ("rrbc_viz.controls", "rrbc_viz.planning_panel", "rrbc_viz.diagnosis_panel", "rrbc_viz.actions"):
        assert "rrbc_viz.app" not in graph[panel], panel
