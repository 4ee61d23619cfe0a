"""The suite's markers say what a test needs: every test that runs Mitsuba or Dr.Jit (a
renderer, a variant, a kernel) is marked ``render``, so that ``-m "not render"`` runs
without them."""

from __future__ import annotations

import ast

from .support import ROOT

#: Names whose use means a test runs Mitsuba or Dr.Jit.
MITSUBA_NAMES = {"Renderer", "use_variant", "render_views", "Silhouettes", "kernel_census", "mitsuba", "drjit"}


def _runs_mitsuba(node: ast.AST) -> bool:
    """Whether code imports Mitsuba or Dr.Jit, names one of :data:`MITSUBA_NAMES`, or asks
    for the device (``device=True``)."""
    for n in ast.walk(node):
        if isinstance(n, ast.Import) and any(a.name.split(".")[0] in ("mitsuba", "drjit") for a in n.names):
            return True
        if isinstance(n, ast.ImportFrom) and (n.module or "").split(".")[0] in ("mitsuba", "drjit"):
            return True
        if isinstance(n, ast.Call) and ast.unparse(n.func).endswith("importorskip") and n.args and \
                isinstance(n.args[0], ast.Constant) and n.args[0].value in ("mitsuba", "drjit"):
            return True
        if isinstance(n, ast.Name) and n.id in MITSUBA_NAMES:
            return True
        if isinstance(n, ast.keyword) and n.arg == "device" and isinstance(n.value, ast.Constant) and n.value.value:
            return True
    return False


def unmarked_mitsuba_tests(source: str) -> list[str]:
    """The tests of a module that run Mitsuba or Dr.Jit (themselves, or through the module's
    helpers and fixtures they name, to any depth) without the ``render`` mark on them, on
    one of their parameters or on the module."""
    tree = ast.parse(source)
    functions = {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}
    module_marked = any(isinstance(n, ast.Assign) and any(getattr(t, "id", "") == "pytestmark" for t in n.targets)
                        and "render" in ast.unparse(n.value) for n in tree.body)

    def reaches(name: str, seen: set[str]) -> bool:
        node = functions[name]
        if _runs_mitsuba(node):
            return True
        named = {n.id for n in ast.walk(node) if isinstance(n, ast.Name)} | {a.arg for a in node.args.args}
        return any(reaches(other, seen | {other}) for other in named & set(functions) - seen)

    return [name for name, node in functions.items()
            if name.startswith("test") and not module_marked
            and not any("mark.render" in ast.unparse(d) for d in node.decorator_list)
            and reaches(name, {name})]


def test_a_test_that_runs_mitsuba_through_a_helper_is_found_unmarked() -> None:
    source = ("import pytest\n"
              "def _scene():\n    from datagen.render.renderer import Renderer\n    return Renderer\n"
              "def test_a(): _scene()\n"
              "@pytest.mark.render\ndef test_b(): _scene()\n"
              "def test_c(): assert 'Renderer'\n")
    assert unmarked_mitsuba_tests(source) == ["test_a"]


def test_every_test_that_runs_mitsuba_or_drjit_is_marked_render() -> None:
    offenders = {p.name: found for p in sorted((ROOT / "tests").glob("test_*.py"))
                 if p.name != "test_markers.py" and (found := unmarked_mitsuba_tests(p.read_text()))}
    assert offenders == {}
