"""The public API (`rrbc_core.__all__`): every name imports, is documented, and the README's example runs."""

from __future__ import annotations

import inspect
import re
import subprocess
import sys

import pytest

import rrbc_core
from tests.paths import ROOT

NAMES = [n for n in rrbc_core.__all__ if n != "__version__"]


def test_version_is_the_installed_distributions():
    from importlib.metadata import version

    assert rrbc_core.__version__ == version("rrbc")


def test_all_and_the_lazy_table_agree():
    assert set(NAMES) == set(rrbc_core._EXPORTS)
    assert set(NAMES) <= set(dir(rrbc_core))


@pytest.mark.parametrize("name", NAMES)
def test_each_exported_name_imports_and_is_documented(name):
    obj = getattr(rrbc_core, name)
    assert getattr(obj, "__name__", name) == name
    doc = inspect.getdoc(obj) or ""
    assert len(doc) > 40, f"{name} has no real docstring"
    assert not doc.startswith(f"{name}("), f"{name} has only the dataclass signature as its docstring"
    if inspect.isfunction(obj) and inspect.signature(obj).parameters:
        for section in ("Parameters\n----------", "Returns\n-------"):
            assert section in doc or (section.startswith("Returns") and "Raises\n------" in doc), (
                f"{name}: numpydoc section {section.splitlines()[0]!r} missing"
            )
        params = [
            p for p in inspect.signature(obj).parameters.values() if p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)
        ]
        for p in params:
            assert re.search(rf"^{re.escape(p.name)}\b|, {re.escape(p.name)}\b", doc, re.M), (
                f"{name}: parameter {p.name!r} not documented"
            )


def test_importing_the_package_stays_light():
    code = "import sys, rrbc_core; print(sorted(m for m in ('scipy', 'open3d', 'numba', 'viser') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def test_the_readme_library_example_runs(tmp_path):
    """The README's 'From Python' block, run as it stands against the bundled example file."""
    text = (ROOT / "README.md").read_text()
    block = re.search(r"### From Python\n.*?```python\n(.*?)```", text, re.S)
    assert block, "README has no 'From Python' example"
    code = block.group(1)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert len(lines) >= 2 and all(
        re.match(r"^\S+ +-?\d+\.\d+ +-?\d+\.\d+ +-?\d+\.\d+$", line) for line in lines[1:]
    ), out.stdout


@pytest.mark.parametrize("name", [n for n in NAMES if inspect.isfunction(getattr(rrbc_core, n))])
def test_each_exported_function_is_typed(name):
    sig = inspect.signature(getattr(rrbc_core, name))
    untyped = [p.name for p in sig.parameters.values() if p.annotation is p.empty and p.kind is not p.VAR_KEYWORD]
    assert not untyped and sig.return_annotation is not sig.empty, f"{name}: untyped {untyped or 'return'}"


@pytest.mark.slow
def test_a_type_checker_sees_the_signatures_of_thread_limited_entry_points(tmp_path):
    """`@thread_limited` keeps the wrapped function's signature for a type checker (a ParamSpec): a wrong call to a
    public entry point is an error mypy reports, a right one is not."""
    from rrbc_core.correction.pipeline import correct_measurements

    assert getattr(correct_measurements, "__wrapped__", None) is not None  # it is a thread_limited entry point
    snippet = tmp_path / "calls.py"
    snippet.write_text(
        "from rrbc_core import correct_measurements, read_measurements\n"
        "good = correct_measurements(read_measurements('x.csv'))\n"
        "bad = correct_measurements(1, 2, 3, 4, 5, 6, wrong=True)\n"
    )
    out = subprocess.run(  # incremental, with the project's mypy cache (warm after CI's own mypy step)
        [sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml"), str(snippet)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    errors = [line for line in out.stdout.splitlines() if ": error:" in line]
    assert errors and all(":3:" in line for line in errors), out.stdout
    assert any("wrong" in line for line in errors), out.stdout
