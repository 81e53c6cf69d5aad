"""The package's shape: no import cycle between its modules, no module too long to read.

Both read the source (``ast``), not the imported package, so that an import made only
inside a function or under ``TYPE_CHECKING`` counts as well.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

import kinecal

SRC = Path(kinecal.__file__).resolve().parent.parent
MAX_LINES = 600  # STYLE: aim under 500, 600 the hard stop for this wave
LINE_COUNT_EXEMPT: tuple[str, ...] = ()  # every module counts


def _modules(root: Path = SRC, package: str = "kinecal") -> dict[str, Path]:
    """Dotted name -> file of every module and package of ``package`` (under ``root``)."""
    out = {}
    for f in sorted((root / package).rglob("*.py")):
        parts = f.relative_to(root).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The kinecal modules ``name`` imports, anywhere in its source.

    ``from a.b import c`` is an import of the module ``a.b.c`` where there is one, else of
    ``a.b``. A module's own ancestor packages are left out: Python initialises them before
    the module itself runs, so importing them orders nothing.
    """
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join([*base, *([node.module] if node.module else [])])
            else:
                module = node.module or ""
            for a in node.names:
                sub = f"{module}.{a.name}"
                found.add(sub if sub in modules else module)
    return {
        m for m in found if m in modules and m != name and not name.startswith(m + ".")
    }


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


@functools.cache  # parsed once for the tests below, which only read it
def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _cycles(graph) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_issue_19_no_import_cycle_between_kinecal_modules():
    graph = _graph()
    assert len(graph) > 50 and "kinecal.models._kernel" in graph
    assert _cycles(graph) == []


def test_issue_32_no_import_cycle_between_the_benchmark_modules():
    """The benchmarks too (``benchmarks/__main__`` and the modules it runs imported one
    another's helpers before)."""
    root = Path(__file__).resolve().parent.parent
    if not (root / "benchmarks").is_dir():
        pytest.skip("no benchmarks folder in this checkout")
    modules = _modules(root, "benchmarks")
    graph = {name: _imports(name, path, modules) for name, path in modules.items()}
    assert "benchmarks.__main__" in graph and "benchmarks._large" in graph
    assert "benchmarks._common" in graph["benchmarks._large"]
    assert _cycles(graph) == []


def test_issue_19_the_cpu_count_sits_below_the_model_and_the_workers():
    """The CPU count and the kernel's thread setting import nothing of kinecal; the
    worker processes and the kernel both use them, and the model never imports the
    workers' module (the circle _parallel -> models._kernel -> models._model before)."""
    graph = _graph()
    assert graph["kinecal._cpu"] == set()
    assert "kinecal._cpu" in graph["kinecal._parallel"]
    assert "kinecal._cpu" in graph["kinecal.models._kernel"]
    models = [m for m in graph if m.startswith("kinecal.models")]
    assert not [m for m in models if "kinecal._parallel" in graph[m]]


def test_issue_19_the_kernel_reads_only_the_model_definition():
    """No ``model._private`` in the compiled kernel's Python side: it takes the public
    ModelDefinition (and the façade module is not imported there)."""
    graph = _graph()
    assert "kinecal.models._model" not in graph["kinecal.models._kernel"]
    assert "kinecal.models._definition" in graph["kinecal.models._kernel"]
    src = (SRC / "kinecal/models/_kernel.py").read_text()
    tree = ast.parse(src)
    private = sorted(
        {
            f"{n.value.id}.{n.attr}"
            for n in ast.walk(tree)
            if isinstance(n, ast.Attribute)
            and isinstance(n.value, ast.Name)
            and n.value.id in ("defn", "model")
            and n.attr.startswith("_")
        }
    )
    assert private == []


def test_issue_19_no_module_over_600_lines():
    too_long = {}
    for path in sorted((SRC / "kinecal").rglob("*.py")):
        rel = path.relative_to(SRC).as_posix()
        if rel.startswith(LINE_COUNT_EXEMPT):
            continue
        lines = len(path.read_text().splitlines())
        if lines > MAX_LINES:
            too_long[rel] = lines
    assert too_long == {}


# Issue 32 point 2: the vocabulary (measurement/) sits below the fitter (identification/).
EDGE_PACKAGES = (
    "cli",
    "compensation",
    "io",
    "iso9283",
    "planning",
    "report",
    "sensor",
    "simulation",
    "workflows",
)


def _vocabulary_from_the_fitter(source: str) -> list[str]:
    """The measurement names ``source`` imports from ``kinecal.identification``."""
    import kinecal.measurement

    vocabulary = set(kinecal.measurement.__all__)
    return [
        a.name
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.ImportFrom)
        and (node.module or "").startswith("kinecal.identification")
        for a in node.names
        if a.name in vocabulary
    ]


def test_issue_32_the_vocabulary_check_finds_an_edge_import():
    probe = "def f():\n    from kinecal.identification import Measurements, calibrate\n"
    assert _vocabulary_from_the_fitter(probe) == ["Measurements"]
    assert _vocabulary_from_the_fitter("from kinecal.measurement import Weights") == []


def test_issue_32_edge_packages_import_the_vocabulary_from_measurement():
    found = {}
    for package in EDGE_PACKAGES:
        for path in sorted((SRC / "kinecal" / package).rglob("*.py")):
            names = _vocabulary_from_the_fitter(path.read_text())
            if names:
                found[path.relative_to(SRC).as_posix()] = names
    assert found == {}, "import these from kinecal.measurement"


def test_issue_32_measurement_imports_nothing_from_identification():
    modules = _modules()
    found = {
        name: sorted(m for m in _imports(name, path, modules) if "identification" in m)
        for name, path in modules.items()
        if name.startswith("kinecal.measurement")
    }
    assert found and all(found), "no measurement module found"
    assert {k: v for k, v in found.items() if v} == {}


def test_issue_32_identification_re_exports_the_vocabulary_unchanged():
    import kinecal.identification
    import kinecal.measurement

    for name in kinecal.measurement.__all__:
        assert name in kinecal.identification.__all__
        assert getattr(kinecal.identification, name) is getattr(
            kinecal.measurement, name
        )


# Issue 32: no function over 100 lines (``def`` to its last line, docstring included).
MAX_FUNCTION_LINES = 100
# Temporary: files other helpers of a wave edit; empty when every branch is merged.
FUNCTION_LENGTH_OTHERS: tuple[str, ...] = ()
# Temporary: functions not yet split into named steps (issue 32, still open).
FUNCTION_LENGTH_NOT_YET_SPLIT: dict[str, tuple[str, ...]] = {}


def _long_functions(source: str, limit: int = MAX_FUNCTION_LINES) -> dict[str, int]:
    """Name -> lines of every function (methods and nested ones too) over ``limit``."""
    return {
        node.name: node.end_lineno - node.lineno + 1
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.end_lineno is not None
        and node.end_lineno - node.lineno + 1 > limit
    }


def test_issue_32_the_length_check_finds_a_long_function():
    body = "".join(f"    x{i} = {i}\n" for i in range(100))
    assert _long_functions(f"def f():\n{body}") == {"f": 101}
    assert _long_functions(f"def f():\n{body[: -len('    x99 = 99') - 1]}") == {}


def test_issue_32_no_function_over_100_lines():
    too_long = {}
    for path in sorted((SRC / "kinecal").rglob("*.py")):
        rel = path.relative_to(SRC).as_posix()
        if rel.startswith(FUNCTION_LENGTH_OTHERS):
            continue
        allowed = FUNCTION_LENGTH_NOT_YET_SPLIT.get(rel, ())
        found = _long_functions(path.read_text())
        too_long.update({f"{rel}:{n}": k for n, k in found.items() if n not in allowed})
    assert too_long == {}


def test_issue_32_the_not_yet_split_list_holds_only_long_functions():
    stale = [
        f"{rel}:{name}"
        for rel, names in FUNCTION_LENGTH_NOT_YET_SPLIT.items()
        for name in names
        if name not in _long_functions((SRC / rel).read_text())
    ]
    assert stale == [], "split: remove from FUNCTION_LENGTH_NOT_YET_SPLIT"


# Issue 32 point 3c: model selection and cross-validation are a package on top of the
# fitter, built on its public helpers.
SELECTION = "kinecal.identification.selection"


def _in_selection(module: str) -> bool:
    return module == SELECTION or module.startswith(SELECTION + ".")


def _names_not_public(source: str, modules: dict[str, Path]) -> list[str]:
    """``module.name`` of every name ``source`` imports from a kinecal module that does not
    list it in its ``__all__`` (no ``__all__``: whose name starts with ``_``); an import
    of a submodule (``from kinecal import _lazy``) is not a name."""
    bad = []
    for node in ast.walk(ast.parse(source)):
        if not (isinstance(node, ast.ImportFrom) and node.module in modules):
            continue
        public = _all_of(modules[node.module])
        for a in node.names:
            if f"{node.module}.{a.name}" in modules:
                continue
            if a.name not in public if public is not None else a.name.startswith("_"):
                bad.append(f"{node.module}.{a.name}")
    return bad


def _all_of(path: Path) -> list[str] | None:
    """The literal ``__all__`` of a module's source, or None."""
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            return list(ast.literal_eval(node.value))
    return None


def test_issue_32_the_public_name_check_finds_a_private_import():
    modules = _modules()
    probe = (
        "from kinecal.identification._solve import run_lm\n"
        "from kinecal.identification.selection._foldfit import FoldStep\n"
        "from kinecal import _lazy\n"
    )
    assert _names_not_public(probe, modules) == []
    probe += (
        "from kinecal.identification._robust import _loo_rms\n"
        "from kinecal.identification.selection._select import _Scorer\n"
    )
    assert _names_not_public(probe, modules) == [
        "kinecal.identification._robust._loo_rms",
        f"{SELECTION}._select._Scorer",
    ]


def test_issue_32_model_selection_is_a_package_on_public_helpers():
    """Its modules import only names the other modules export (the fitter's public
    helpers, one another's public names), and nothing in kinecal or its tests imports a
    private name of theirs."""
    modules = _modules()
    own = {m: p for m, p in modules.items() if _in_selection(m)}
    assert {f"{SELECTION}._select", f"{SELECTION}._crossval"} <= set(own)
    found = {m: _names_not_public(p.read_text(), modules) for m, p in own.items()}
    assert {m: v for m, v in found.items() if v} == {}
    tests = Path(__file__).resolve().parent
    users = [*modules.values(), *sorted(tests.rglob("*.py"))]
    found = {p.name: _names_not_public(p.read_text(), own) for p in users}
    assert {m: v for m, v in found.items() if v} == {}


def test_issue_32_the_fitter_does_not_import_model_selection():
    """Selection calibrates through the fitter; no module of the fitter imports it (the
    identification package re-exports its names, importing them on first use)."""
    graph = _graph()
    fitter = [
        m
        for m in graph
        if m.startswith("kinecal.identification.") and not _in_selection(m)
    ]
    assert "kinecal.identification._calibrate" in fitter and len(fitter) > 15
    found = {m: sorted(d for d in graph[m] if _in_selection(d)) for m in fitter}
    assert {m: v for m, v in found.items() if v} == {}
    assert "kinecal.identification._calibrate" in graph[f"{SELECTION}._select"]
    # the fitter's leave-one-out errors (PRESS) serve the fit itself: they stay there
    assert "kinecal.identification._press" in graph["kinecal.identification._noise"]


# Issue 32: the command line parses options, checks arguments and prints; the work is
# in workflows/ (cli/ was 3,579 lines).
MAX_CLI_LINES = 3200


def test_issue_32_cli_at_most_3200_lines():
    counts = {
        p.name: len(p.read_text().splitlines())
        for p in sorted((SRC / "kinecal" / "cli").rglob("*.py"))
    }
    assert len(counts) > 10, "cli/ not found"
    total = sum(counts.values())
    assert total <= MAX_CLI_LINES, f"cli/ has {total} lines: {counts}"


def test_issue_32_every_public_workflow_function_is_fully_annotated():
    """Issue 32 must-show: each command's workflow is a typed function (every parameter
    and the return annotated); the result types are classes."""
    import inspect

    import kinecal.workflows as wf

    missing = []
    for name in wf.__all__:
        obj = getattr(wf, name)
        if inspect.isclass(obj) or not callable(obj):
            continue
        sig = inspect.signature(obj)
        for p in sig.parameters.values():
            if p.annotation is inspect.Parameter.empty:
                missing.append(f"{name}({p.name})")
        if sig.return_annotation is inspect.Signature.empty:
            missing.append(f"{name} -> ?")
    assert missing == []
