"""The code's structure, read from its syntax trees (``ast``, nothing imported): no import cycle among
aogm's modules; mapping, the sensor models and the detector never import ``aogm_cli.io``; only ``io``
and ``cli`` write files; every function that is neither a numba kernel nor a click command has at
most 60 lines and 8 parameters. Each failure names the module, function and line."""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "aogm_cli"

MAX_LINES = 60
MAX_PARAMS = 8
NO_IO = ("aogm_cli.mapping", "aogm_cli.sensor_models", "aogm_cli.detector")  # never import aogm_cli.io
WRITERS = ("aogm_cli.io", "aogm_cli.cli")  # the only packages that write files
NUMBA_DECORATORS = {"njit", "jit", "vectorize", "guvectorize", "cfunc", "stencil", "generated_jit", "overload",
                    "overload_method", "intrinsic"}
CLICK_DECORATORS = {"command", "group", "option", "argument"}


@dataclass(frozen=True)
class Import:
    """One import statement's edge: ``source`` imports ``target`` (both aogm modules) at ``line``;
    ``runtime`` is False for imports under ``if TYPE_CHECKING:``."""

    source: str
    target: str
    line: int
    runtime: bool


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@cache
def modules() -> dict[str, Path]:
    """Every aogm module by its dotted name (a package by its ``__init__.py``)."""
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


@cache
def tree(name: str) -> ast.Module:
    path = modules()[name]
    return ast.parse(path.read_text(), filename=str(path))


def relative(path: Path) -> str:
    return str(path.relative_to(ROOT))


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _import_nodes(node: ast.AST, runtime: bool = True):
    """(Import or ImportFrom node, runtime) anywhere in ``node``: module level, in functions and
    classes; ``runtime`` False under ``if TYPE_CHECKING:``."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.Import | ast.ImportFrom):
            yield child, runtime
        elif isinstance(child, ast.If) and _is_type_checking(child.test):
            for stmt in child.body:
                yield from _import_nodes(ast.Module(body=[stmt], type_ignores=[]), False)
            for stmt in child.orelse:
                yield from _import_nodes(ast.Module(body=[stmt], type_ignores=[]), runtime)
        else:
            yield from _import_nodes(child, runtime)


def _resolve(name: str, node: ast.ImportFrom) -> str:
    """The absolute module an ImportFrom's ``from X`` names, relative ones resolved from ``name``."""
    if not node.level:
        return node.module or ""
    package = name if modules()[name].name == "__init__.py" else name.rpartition(".")[0]
    base = package.split(".")
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def _known(dotted: str) -> str | None:
    """The aogm module ``dotted`` names, or the longest aogm module that prefixes it."""
    parts = dotted.split(".")
    while parts:
        candidate = ".".join(parts)
        if candidate in modules():
            return candidate
        parts.pop()
    return None


@cache
def imports(name: str) -> tuple[Import, ...]:
    """The aogm modules that module ``name`` imports: ``import aogm_cli.a.b`` imports aogm_cli.a.b;
    ``from aogm_cli.a import b`` imports the submodule aogm_cli.a.b when there is one, else aogm_cli.a."""
    found = []
    for node, runtime in _import_nodes(tree(name)):
        if isinstance(node, ast.Import):
            targets = [_known(alias.name) for alias in node.names]
        else:
            base = _resolve(name, node)
            targets = [_known(f"{base}.{alias.name}") if f"{base}.{alias.name}" in modules() else _known(base)
                       for alias in node.names]
        found.extend(Import(name, t, node.lineno, runtime) for t in dict.fromkeys(targets) if t is not None)
    return tuple(found)


def import_cycles() -> list[list[Import]]:
    """One cycle of runtime imports (a list of edges, each from the previous edge's target) per
    strongly connected component of the import graph that has one (Tarjan's algorithm)."""
    graph: dict[str, list[Import]] = {m: [e for e in imports(m) if e.runtime] for m in modules()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for e in graph[v]:
            if e.target not in index:
                connect(e.target)
                low[v] = min(low[v], low[e.target])
            elif e.target in on_stack:
                low[v] = min(low[v], index[e.target])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            components.append(component)

    for v in graph:
        if v not in index:
            connect(v)
    cycles = []
    for component in components:
        members = set(component)
        start = min(component)
        if len(component) == 1 and not any(e.target == start for e in graph[start]):
            continue
        cycles.append(_path_back(graph, members, start))
    return cycles


def _path_back(graph: dict[str, list[Import]], members: set[str], start: str) -> list[Import]:
    """The shortest chain of imports within ``members`` from ``start`` back to ``start``."""
    came: dict[str, Import] = {}
    frontier = [start]
    while frontier:
        following = []
        for v in frontier:
            for e in graph[v]:
                if e.target not in members or e.target in came:
                    continue
                came[e.target] = e
                if e.target == start:
                    chain = [e]
                    while chain[0].source != start:
                        chain.insert(0, came[chain[0].source])
                    return chain
                following.append(e.target)
        frontier = following
    raise AssertionError(f"no cycle through {start}")  # pragma: no cover


def describe_cycle(chain: list[Import]) -> str:
    return " -> ".join(f"{e.source} ({relative(modules()[e.source])}:{e.line})" for e in chain) + f" -> {chain[0].source}"


def test_no_import_cycle():
    cycles = import_cycles()
    assert not cycles, "import cycles (each import at the line named):\n" + "\n".join(map(describe_cycle, cycles))


def in_packages(name: str, packages: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in packages)


def test_mapping_sensor_models_and_detector_do_not_import_io():
    bad = [f"{relative(modules()[e.source])}:{e.line}: {e.source} imports {e.target}"
           for m in modules() if in_packages(m, NO_IO)
           for e in imports(m) if in_packages(e.target, ("aogm_cli.io",))]
    assert not bad, "modules of " + ", ".join(NO_IO) + " import aogm_cli.io:\n" + "\n".join(bad)


def dotted(node: ast.expr) -> str:
    """``a.b.c`` of a name or attribute chain (calls and subscripts in it as ``()``)."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return f"{dotted(node.value)}.{node.attr}"
    if isinstance(node, ast.Call):
        return f"{dotted(node.func)}()"
    return "()"


def _argument(call: ast.Call, position: int, keyword: str) -> ast.expr | None:
    for kw in call.keywords:
        if kw.arg == keyword:
            return kw.value
    return call.args[position] if len(call.args) > position else None


MODE = re.compile(r"[rwxabt+]+")
FILE_OPENERS = ("open", "io.open", "os.fdopen", "gzip.open", "bz2.open", "lzma.open", "tarfile.open")


def _writes_mode(mode: ast.expr | None, unknown: bool) -> bool:
    """Whether an open mode writes: a constant mode with w, a, x or +; another expression: ``unknown``."""
    if isinstance(mode, ast.Constant) and isinstance(mode.value, str) and MODE.fullmatch(mode.value):
        return any(c in mode.value for c in "wax+")
    return mode is not None and unknown


def file_write(call: ast.Call) -> str | None:
    """What a call writes to a file, or None: ``open`` with a write mode, numpy's save*,
    ``h5py.File`` not read-only, ``os.replace``, ``.mkdir``, ``.write_text``, ``.write_bytes``."""
    name = dotted(call.func)
    last = name.rpartition(".")[2]
    if name in FILE_OPENERS:  # open(file, mode): a mode that is not a constant may write
        return f"{name}(...) with a write mode" if _writes_mode(_argument(call, 1, "mode"), True) else None
    if last == "open" and isinstance(call.func, ast.Attribute):  # Path.open(mode): a constant write mode
        return f"{name}(...) with a write mode" if _writes_mode(_argument(call, 0, "mode"), False) else None
    if name in ("np.save", "np.savez", "np.savez_compressed", "np.savetxt", "numpy.save", "numpy.savez",
                "numpy.savez_compressed", "numpy.savetxt"):
        return f"{name}(...)"
    if name in ("h5py.File",):
        mode = _argument(call, 1, "mode")
        writes = mode is not None and not (isinstance(mode, ast.Constant) and mode.value == "r")
        return "h5py.File(...) not read-only" if writes else None
    if name in ("os.replace", "os.rename", "os.makedirs", "os.mkdir"):
        return f"{name}(...)"
    if isinstance(call.func, ast.Attribute) and last in ("mkdir", "write_text", "write_bytes"):
        return f".{last}(...)"
    return None


def functions(node: ast.AST, scope: str = ""):
    """(qualified name, function node, enclosing class or None) of every function in ``node``."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
            owner = node if isinstance(node, ast.ClassDef) else None
            yield f"{scope}{child.name}", child, owner
            yield from functions(child, f"{scope}{child.name}.")
        elif isinstance(child, ast.ClassDef):
            yield from functions(child, f"{scope}{child.name}.")
        else:
            yield from functions(child, scope)


def enclosing_function(tree_: ast.Module, line: int) -> str:
    """The innermost function around ``line`` (its qualified name), or "<module>"."""
    best = "<module>"
    for qualified, fn, _ in functions(tree_):
        if fn.lineno <= line <= fn.end_lineno:
            best = qualified  # ``functions`` yields outer functions before inner ones
    return best


def test_no_file_is_written_outside_io_and_cli():
    bad = []
    for m, path in modules().items():
        if in_packages(m, WRITERS):
            continue
        t = tree(m)
        for node in ast.walk(t):
            if isinstance(node, ast.Call) and (what := file_write(node)):
                bad.append(f"{relative(path)}:{node.lineno}: {m}.{enclosing_function(t, node.lineno)} calls {what}")
    assert not bad, "files written outside " + " and ".join(WRITERS) + ":\n" + "\n".join(sorted(bad))


def _decorator_name(node: ast.expr) -> str:
    return dotted(node.func if isinstance(node, ast.Call) else node)


def exempt(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    """Numba kernels (``numba.njit``, ``njit``, ``numba.vectorize``, ...) and click commands
    (``click.command``/``group``/``option``/``argument``, a decorator named ``...option(s)`` or
    ``...command``) may be long or take many parameters."""
    for decorator in fn.decorator_list:
        name = _decorator_name(decorator)
        last = name.rpartition(".")[2]
        if name.startswith("numba.") or last in NUMBA_DECORATORS:
            return True
        if (name.startswith("click.") and last in CLICK_DECORATORS) or last.endswith(("option", "options", "command")):
            return True
    return False


def parameter_count(fn: ast.FunctionDef | ast.AsyncFunctionDef, method: bool) -> int:
    a = fn.args
    names = [p.arg for p in (*a.posonlyargs, *a.args)]
    if method and names and names[0] in ("self", "cls"):
        names = names[1:]
    return len(names) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)


def test_functions_are_short_and_take_few_parameters():
    bad = []
    for m, path in modules().items():
        for qualified, fn, owner in functions(tree(m)):
            if exempt(fn):
                continue
            where = f"{relative(path)}:{fn.lineno}: {m}.{qualified}"
            lines = fn.end_lineno - fn.lineno + 1
            if lines > MAX_LINES:
                bad.append(f"{where} has {lines} lines (at most {MAX_LINES})")
            count = parameter_count(fn, owner is not None)
            if count > MAX_PARAMS:
                bad.append(f"{where} has {count} parameters (at most {MAX_PARAMS})")
    assert not bad, "functions too long or with too many parameters:\n" + "\n".join(bad)


# the checks themselves, on small sources


def _calls(source: str) -> list[str | None]:
    return [file_write(n) for n in ast.walk(ast.parse(source)) if isinstance(n, ast.Call)]


def test_the_file_write_check_finds_writes_and_passes_reads():
    writes = ['open(p, "w")', 'open(p, mode="ab")', 'p.open("w")', 'gzip.open(p, "wt")', "np.save(p, a)",
              "np.savez(f, **arrays)", 'h5py.File(p, "w")', 'h5py.File(p, mode="a")', "os.replace(a, b)",
              "p.parent.mkdir(parents=True)", 'p.write_text("x")', 'p.write_bytes(b"x")', "open(p, mode)"]
    reads = ["open(p)", 'open(p, "rb")', 'p.open("r")', "p.open()", 'h5py.File(p, "r")', "h5py.File(p)",
             "np.load(p)", "p.read_text()"]
    assert all(_calls(s) == [_calls(s)[0]] and _calls(s)[0] for s in writes), [(s, _calls(s)) for s in writes]
    assert all(not any(_calls(s)) for s in reads), [(s, _calls(s)) for s in reads]


def test_the_exemptions_are_numba_kernels_and_click_commands():
    source = """
@numba.njit(cache=True)
def a(): pass
@njit
def b(): pass
@numba.vectorize(["float64(float64)"])
def c(): pass
@click.command()
def d(): pass
@main.command("x")
def e(): pass
@map_options
def f(): pass
@click.option("--x")
def g(): pass
@functools.cache
def h(): pass
def i(): pass
"""
    got = {fn.name: exempt(fn) for fn in ast.parse(source).body}
    assert got == {**dict.fromkeys("abcdefg", True), "h": False, "i": False}


def test_the_parameter_count_leaves_out_self_and_cls_only():
    source = """
class C:
    def m(self, a, b): pass
    def k(cls, a, *args, b, **kw): pass
def f(self, a): pass
"""
    found = {q: parameter_count(fn, owner is not None) for q, fn, owner in functions(ast.parse(source))}
    assert found == {"C.m": 2, "C.k": 4, "f": 2}


def test_the_import_graph_holds_submodules_function_level_imports_and_type_only_ones():
    cli = {(e.target, e.runtime) for e in imports("aogm_cli.cli")}
    assert ("aogm_cli.core.interrupts", True) in cli  # from aogm_cli.core import interrupts: the submodule
    assert ("aogm_cli", True) in cli  # from aogm_cli import __version__: the package itself
    assert ("aogm_cli.io.template_store", True) in cli  # imported inside a function
    api = {(e.target, e.runtime) for e in imports("aogm_cli.api")}
    assert ("aogm_cli.core.log", False) in api and ("aogm_cli.core.log", True) not in api  # under TYPE_CHECKING
