"""The package layout keeps its promises: the pure stages import without Mitsuba or
matplotlib, only ``datagen.render`` talks to Mitsuba, every file write goes through
``datagen.atomic`` from the dataset writer and the report writers, no import sets
process-wide state, and conventions are used from their one place (the overlay's
crosshair sits on the true centre)."""

from __future__ import annotations

import ast
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from .strategies import finite
from .support import ROOT

PACKAGE = ROOT / "datagen"


def modules() -> dict[str, ast.Module]:
    """Every module of the package, by path relative to ``datagen/``."""
    return {str(p.relative_to(PACKAGE)): ast.parse(p.read_text()) for p in sorted(PACKAGE.rglob("*.py"))}


def imported(tree: ast.Module) -> set[str]:
    """The top-level names of every module a module imports (at any depth in its code)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_the_pure_stages_import_without_mitsuba_drjit_or_matplotlib() -> None:
    pure = [f"datagen.{m.removesuffix('.py').replace('/', '.')}" for m in modules()
            if m.split("/")[0] in ("core", "config", "scene", "dataset") and not m.endswith("__init__.py")]
    code = ("import sys\n" + "".join(f"import {m}\n" for m in pure)
            + "print(sorted({m.split('.')[0] for m in sys.modules} & {'mitsuba', 'drjit', 'matplotlib'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", f"{len(pure)} pure modules imported {out.stdout.strip()}"
    assert len(pure) >= 15


def test_only_the_render_package_imports_mitsuba_or_drjit() -> None:
    offenders = [path for path, tree in modules().items()
                 if {n.split(".")[0] for n in imported(tree)} & {"mitsuba", "drjit"} and not path.startswith("render/")]
    assert offenders == []
    assert any({"mitsuba", "drjit"} & {n.split(".")[0] for n in imported(tree)} for p, tree in modules().items()
               if p.startswith("render/"))


def datagen_imports(tree: ast.Module) -> set[str]:
    """The datagen modules a module imports, at any depth in its code."""
    return {n for n in imported(tree) if n.startswith("datagen.")}


def package_of(path_or_module: str) -> str:
    """``dataset`` for ``dataset/reader.py`` or ``datagen.dataset.reader``; ``atomic`` for ``atomic.py``."""
    parts = (path_or_module.removeprefix("datagen.").split(".") if "/" not in path_or_module
             and not path_or_module.endswith(".py") else path_or_module.removesuffix(".py").split("/"))
    return parts[0]


#: The packages from the bottom up: a package imports only packages of a lower rank (the
#: build, ``pipeline``, and the reading commands, ``analysis``, share a rank and import neither
#: the other); ``cli`` and the package's own ``__init__``/``__main__`` sit on top.
RANKS = {"core": 0, "atomic": 1, "paths": 1, "parallel": 1, "console": 1, "config": 2, "dataset": 3, "assets": 4,
         "scene": 5, "render": 6, "pipeline": 7, "analysis": 7, "report": 8, "cli": 9, "__init__": 10, "__main__": 10}


def test_every_package_imports_only_packages_below_it() -> None:
    upward = []
    for path, tree in modules().items():
        me = package_of(path)
        for target in datagen_imports(tree):
            other = package_of(target)
            if other != me and RANKS[other] >= RANKS[me]:
                upward.append(f"{path} imports {target}")
    assert set(package_of(p) for p in modules()) <= set(RANKS)
    assert upward == []


def test_the_dataset_contract_imports_only_core_config_inputs_files_and_paths() -> None:
    """``dataset/`` is the on-disk contract: reading a dataset needs no scene, renderer,
    build or config schema."""
    allowed = ("datagen.core.", "datagen.dataset.")
    offenders = {path: sorted(t for t in datagen_imports(tree)
                              if not t.startswith(allowed)
                              and t not in ("datagen.config.inputs", "datagen.atomic", "datagen.paths"))
                 for path, tree in modules().items() if path.startswith("dataset/")}
    assert {p: o for p, o in offenders.items() if o} == {}
    assert len(offenders) >= 4


def test_reading_a_dataset_or_auditing_one_loads_no_simulator_and_no_build() -> None:
    code = ("import sys\nimport datagen.dataset.reader, datagen.analysis.audit, datagen.analysis.evaluate\n"
            "print(sorted({'.'.join(m.split('.')[:2]) for m in sys.modules if m.startswith('datagen.')}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    loaded = set(ast.literal_eval(out.stdout.strip()))
    assert "datagen.dataset" in loaded and "datagen.analysis" in loaded
    assert loaded & {"datagen.scene", "datagen.render", "datagen.pipeline", "datagen.assets"} == set()


def test_the_module_import_graph_has_no_cycles() -> None:
    """Counting every import, at any depth in a module's code (a deferred import too)."""
    names = {f"datagen.{p.removesuffix('.py').replace('/', '.')}".removesuffix(".__init__"): tree
             for p, tree in modules().items()}
    graph = {m: {t for t in datagen_imports(tree) if t in names and t != m} for m, tree in names.items()}
    state: dict[str, int] = {}  # 1 on the current path, 2 done
    cycles = []

    def visit(m: str, path: list[str]) -> None:
        state[m] = 1
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                cycles.append(" -> ".join([*path[path.index(t):], t]))
            elif t not in state:
                visit(t, [*path, t])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert cycles == []


#: Calls that write a file (or create one), wherever they appear.
WRITE_CALLS = {"write_text", "write_bytes", "savefig", "imwrite", "write_table", "write_to_dataset"}
#: The functions of datagen.atomic that write.
WRITERS = {"atomic_path", "write_bytes", "write_text", "write_parquet", "write_exr", "write_image", "write_figure",
           "scratch_file"}


def writes(tree: ast.Module) -> list[str]:
    """Write calls in a module: file-writing methods, ``open`` for writing, ``os.open`` with O_CREAT."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        name = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""
        if name in WRITE_CALLS and not (isinstance(func, ast.Name)):
            found.append(name)
        if name == "open" and isinstance(func, ast.Name):
            mode = node.args[1] if len(node.args) > 1 else next((k.value for k in node.keywords if k.arg == "mode"),
                                                                None)
            target = ast.unparse(node.args[0]) if node.args else ""
            if isinstance(mode, ast.Constant) and set(str(mode.value)) & set("wax+") and target != "os.devnull":
                found.append(f"open(mode={mode.value!r})")
        if name == "open" and isinstance(func, ast.Attribute) and ast.unparse(func) == "os.open":
            flags = ast.unparse(node.args[1]) if len(node.args) > 1 else ""
            if any(f in flags for f in ("O_CREAT", "O_WRONLY", "O_RDWR", "O_TRUNC", "O_APPEND")):
                found.append("os.open")
    return found


def test_every_file_write_goes_through_one_module_called_by_the_writers() -> None:
    """``datagen/atomic.py`` writes (and ``pipeline/folder.py`` creates the lock); the modules
    that call its writers are the dataset writer (``dataset/``, ``pipeline/``), the
    report writers (``report/``), the asset writer (``assets/generate.py``) and the audit's
    spill of values into a private temporary folder (``analysis/exact.py``)."""
    primitives = {path: found for path, tree in modules().items() if (found := writes(tree))}
    assert set(primitives) == {"atomic.py", "pipeline/folder.py"}, primitives
    assert primitives["pipeline/folder.py"] == ["os.open"]  # the lock file
    callers = set()
    for path, tree in modules().items():
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module == "datagen.atomic" and \
                    {a.name for a in node.names} & WRITERS:
                callers.add(path)
    allowed = {p for p in callers if p.startswith(("dataset/", "pipeline/", "report/"))} | {"assets/generate.py",
                                                                                     "analysis/exact.py"}
    assert callers <= allowed, callers - allowed
    assert {"pipeline/writer.py", "pipeline/metadata.py", "report/plots.py"} <= callers


#: Calls that set process-wide state; only these modules may hold them, inside functions.
PROCESS_STATE = {"set_variant": {"render/runtime.py"}, "set_thread_count": {"render/runtime.py"},
                 "use": set(), "signal": {"pipeline/executors.py"}, "seed": set()}


def test_no_module_sets_process_wide_state_at_import() -> None:
    """No call at module level besides definitions (and no pyplot, no global RNG); the
    Mitsuba variant, Dr.Jit's threads and signal handlers are set in one module each."""
    for path, tree in modules().items():
        for node in (tree.body if path != "__main__.py" else []):  # module level: imports, definitions, constants
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Call):
                func = ast.unparse(node.value.func)
                if (path == "cli/common.py" and func == "app.add_typer") or func.endswith(".setflags"):
                    continue  # assembling the command line object; freezing a constant array
                pytest.fail(f"{path}:{node.lineno}: a call at import time: {ast.unparse(node)[:80]}")
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                name, owner = node.func.attr, ast.unparse(node.func.value)
                if name in ("set_variant", "set_thread_count"):
                    assert path == "render/runtime.py", f"{path}: {ast.unparse(node)}"
                if owner == "signal" and name == "signal":
                    assert path == "pipeline/executors.py", f"{path}: {ast.unparse(node)}"
                if owner in ("np.random", "numpy.random", "random") and name in ("seed", "random", "uniform",
                                                                              "default_rng") \
                        and path != "core/conventions.py":
                    pytest.fail(f"{path}: {ast.unparse(node)}: every RNG stream is in datagen.core.conventions")
        assert "matplotlib.pyplot" not in imported(tree), path


def test_cached_frame_states_are_read_only() -> None:
    from datagen.config import load_config
    from datagen.scene.approach import FrameStates

    states = FrameStates(load_config(ROOT / "scenes" / "wingcam55.yaml"))
    state = states(3)
    for name in ("world_from_tanker", "world_from_receiver", "world_from_drogue", "world_from_cam",
                 "hose_points_world", "ptd_receiver_m"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(state, name)[0] = 1.0
    assert states(3) is state  # the same chain, simulated once


# --- the continuous-pixel to drawing-grid rule ---------------------------------------------------
MAGENTA = np.array([255, 80, 255])


def crosshair_centre(image: np.ndarray, near: np.ndarray, radius: int = 12) -> np.ndarray:
    """Intensity centroid (continuous pixels: pixel (i, j) has its centre at (i + 0.5, j + 0.5))
    of the magenta drawn within ``radius`` of ``near``."""
    x0, y0 = (np.floor(near) - radius).astype(int)
    window = image[y0:y0 + 2 * radius, x0:x0 + 2 * radius].astype(float)
    weight = window[..., 0] * (window[..., 1] < 0.5 * window[..., 0])  # blue, not cyan/green/amber edges
    jj, ii = np.mgrid[0:window.shape[0], 0:window.shape[1]]
    return np.array([(weight * (ii + x0 + 0.5)).sum(), (weight * (jj + y0 + 0.5)).sum()]) / weight.sum()


@given(u=st.floats(40.0, 200.0, **finite), v=st.floats(40.0, 120.0, **finite))
def test_a_drawn_crosshair_is_centred_on_its_continuous_point(u, v) -> None:
    from datagen.report.overlays import draw_crosshair

    image = np.zeros((160, 240, 3), np.uint8)
    draw_crosshair(image, (u, v), tuple(int(c) for c in MAGENTA), arm=6.0, thickness=1)
    np.testing.assert_allclose(crosshair_centre(image, np.array([u, v])), [u, v], atol=0.1)


def test_write_bytes_makes_its_folder_replaces_atomically_and_leaves_no_temporary(tmp_path) -> None:
    from datagen.atomic import is_temporary, write_bytes, write_text

    target = tmp_path / "a" / "b" / "labels.txt"
    assert write_text(target, "0 0.5 0.5 0.1 0.1\n") == target
    assert target.read_text() == "0 0.5 0.5 0.1 0.1\n"
    write_bytes(str(target), b"replaced")
    assert target.read_bytes() == b"replaced"
    (tmp_path / "a" / "b" / "dir.txt").mkdir()
    with pytest.raises(IsADirectoryError) as info:  # the rename fails: the error names the target
        write_bytes(tmp_path / "a" / "b" / "dir.txt", b"x")
    assert not any(is_temporary(p.name) for p in (tmp_path / "a" / "b").iterdir())
    assert str(info.value.filename).endswith("dir.txt")
