"""Every public function and method of clvis is fully annotated.

Public: a module-level function or a method of a public class whose name does
not start with "_" (``__init__`` counts too), in a module whose file name does
not start with "_" (``__init__.py`` and ``__main__.py`` count; ``_arrays.py``,
``_common.py``, ``_version.py`` are private). Nested functions are not checked.
Fully annotated: every parameter but a method's self/cls (``*args`` and
``**kwargs`` included) and the return (not ``__init__``'s).

The modules are read with ``ast``, never imported (``__main__.py`` exits when
imported).
"""

from __future__ import annotations

import ast
from collections.abc import Iterator, Sequence
from pathlib import Path

import clvis

PACKAGE = Path(clvis.__file__).resolve().parent
ROOT = PACKAGE.parent

FunctionNode = ast.FunctionDef | ast.AsyncFunctionDef


def _modules() -> list[str]:
    """The public modules of clvis, as paths relative to ROOT."""
    out = []
    for p in sorted(PACKAGE.rglob("*.py")):
        if p.name.startswith("_") and p.name not in ("__init__.py", "__main__.py"):
            continue
        out.append(p.relative_to(ROOT).as_posix())
    return out


MODULES = _modules()


def _definitions(
    body: Sequence[ast.stmt], prefix: str = "", in_class: bool = False
) -> Iterator[tuple[str, FunctionNode, bool]]:
    """(qualified name, node, is a method) of each public function of `body`,
    public classes' methods included, through if/try blocks, not into functions."""
    for n in body:
        if isinstance(n, ast.ClassDef):
            if not n.name.startswith("_"):
                yield from _definitions(n.body, f"{prefix}{n.name}.", True)
        elif isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
            if not n.name.startswith("_") or n.name == "__init__":
                yield prefix + n.name, n, in_class
        elif isinstance(n, ast.If):
            yield from _definitions(n.body + n.orelse, prefix, in_class)
        elif isinstance(n, ast.Try):
            blocks = n.body + [s for h in n.handlers for s in h.body] + n.orelse + n.finalbody
            yield from _definitions(blocks, prefix, in_class)


def _missing(node: FunctionNode, method: bool) -> list[str]:
    """What `node` lacks, in the signature's order: parameter names ("*args",
    "**kwargs") and "return"."""
    a = node.args
    params = a.posonlyargs + a.args
    decorators = {d.id for d in node.decorator_list if isinstance(d, ast.Name)}
    if method and params and "staticmethod" not in decorators and params[0].arg in ("self", "cls"):
        params = params[1:]
    bad = [p.arg for p in params if p.annotation is None]
    if a.vararg is not None and a.vararg.annotation is None:
        bad.append("*" + a.vararg.arg)
    bad += [p.arg for p in a.kwonlyargs if p.annotation is None]
    if a.kwarg is not None and a.kwarg.annotation is None:
        bad.append("**" + a.kwarg.arg)
    if node.returns is None and node.name != "__init__":
        bad.append("return")
    return bad


def offenders(rel: str) -> list[str]:
    """``path:line name: missing ...`` for each public function of module `rel`
    (relative to ROOT) that is not fully annotated."""
    tree = ast.parse((ROOT / rel).read_text(encoding="utf-8"), filename=rel)
    out = []
    for name, node, method in _definitions(tree.body):
        bad = _missing(node, method)
        if bad:
            out.append(f"{rel}:{node.lineno} {name}: missing {', '.join(bad)}")
    return out


def _report(found: list[str]) -> str:
    return f"{len(found)} public functions not fully annotated:\n" + "\n".join(found)


def test_modules_found():
    assert (
        "clvis/__init__.py" in MODULES
        and "clvis/runtime/__init__.py" in MODULES
        and "clvis/runtime/device.py" in MODULES
    )
    assert "clvis/cli/__main__.py" in MODULES
    assert not any(Path(m).name in ("_arrays.py", "_common.py", "_version.py") for m in MODULES)
    for family in ("raster", "gauss", "iso"):
        assert f"clvis/{family}/__init__.py" in MODULES and f"clvis/reference/{family}/__init__.py" in MODULES


def test_checker_finds_what_is_missing(tmp_path):
    src = """
def f(a, b: int, *args, c=1, **kw): pass
def g(x: int) -> int: return x
def _private(a): pass
async def h(a: int): pass
class C:
    def __init__(self, a): pass
    def m(self, a: int) -> None:
        def nested(z): pass
    @staticmethod
    def s(self) -> None: pass
    @classmethod
    def k(cls) -> None: pass
    def _p(self, a): pass
class _Hidden:
    def m(self, a): pass
"""
    tree = ast.parse(src)
    found = {name: _missing(node, method) for name, node, method in _definitions(tree.body)}
    assert found == {
        "f": ["a", "*args", "c", "**kw", "return"],
        "g": [],
        "h": ["return"],
        "C.__init__": ["a"],
        "C.m": [],
        "C.s": ["self"],
        "C.k": [],
    }


def test_public_functions_annotated():
    """Every public module of the package."""
    found = [line for m in MODULES for line in offenders(m)]
    assert not found, _report(found)


# --------------------------------------------------------------------------
# mypy's scope (dev.sh's TYPED): the whole package, nothing switched off


def _typed() -> list[str]:
    import re
    import shlex

    text = (ROOT / "dev.sh").read_text(encoding="utf-8")
    m = re.search(r'^TYPED="(.*?)"', text, re.M | re.S)
    assert m, "dev.sh has no TYPED list"
    return shlex.split(m.group(1))


def _covered(module: str, typed: list[str]) -> bool:
    return any(
        module == t or (not t.endswith(".py") and module.startswith(t.rstrip("/") + "/")) for t in typed
    )


EVERY_MODULE = sorted(
    p.relative_to(ROOT).as_posix() for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts
)


def outside(typed: list[str]) -> list[str]:
    """The modules of clvis (private ones included) that mypy, given the
    paths `typed`, does not check."""
    return [m for m in EVERY_MODULE if not _covered(m, typed)]


def test_scope_checker_finds_an_omission():
    assert outside(["clvis"]) == [] and outside(["clvis/"]) == []
    every_file = [m for m in EVERY_MODULE]
    assert outside(every_file) == []
    left_out = "clvis/io/las.py"
    assert outside([m for m in every_file if m != left_out]) == [left_out]
    assert "clvis/post/infer.py" in outside(["clvis/raster", "clvis/io", "clvis/iso"])
    assert outside(["clvis/raster.py"]) == EVERY_MODULE  # a file named like a package covers nothing


def test_mypy_scope_is_the_whole_package():
    typed = _typed()
    for t in typed:
        assert (ROOT / t).exists(), f"dev.sh's TYPED names {t}, which does not exist"
    missing = outside(typed)
    assert not missing, f"modules outside mypy's scope (dev.sh's TYPED must cover them): {missing}"


def test_nothing_switched_off():
    """No module is exempt: no ignore_errors (or an ignore_missing_imports) for
    clvis in pyproject.toml, no module-wide ``# mypy:`` comment, and every
    per-line ``# type: ignore`` names its error code."""
    import re

    config = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    assert "ignore_errors" not in config
    mypy_modules = re.findall(r'"([\w.*]+)"', config[config.index("[tool.mypy]") :].split("\n[tool.ruff")[0])
    assert not [m for m in mypy_modules if m == "clvis" or m.startswith("clvis.")], mypy_modules
    bad = []
    for m in EVERY_MODULE:
        for n, line in enumerate((ROOT / m).read_text(encoding="utf-8").splitlines(), 1):
            if re.match(r"\s*#\s*mypy:", line):
                bad.append(f"{m}:{n} a module-wide mypy comment")
            ignore = re.search(r"#\s*type:\s*ignore(\S*)", line)
            if ignore and not ignore.group(1).startswith("["):
                bad.append(f"{m}:{n} a type: ignore without an error code")
    assert not bad, "\n".join(bad)


# --------------------------------------------------------------------------
# what post reads, as Protocols the renderers' results satisfy


def test_post_input_protocols_match_the_results():
    """Each Protocol of clvis.post.inputs names planes its result dataclass
    has, and those planes are typed for host and device arrays (mypy checks
    the rest: tests can't, the lint does)."""
    import dataclasses

    from clvis.iso import IsoImage
    from clvis.post import inputs
    from clvis.raster import FilteredImage, GBuffers

    for proto, result in (
        (inputs.IsoImageLike, IsoImage),
        (inputs.FilteredImageLike, FilteredImage),
        (inputs.GBuffersLike, GBuffers),
    ):
        planes = {n for n, v in vars(proto).items() if isinstance(v, property)}
        fields = {f.name: str(f.type) for f in dataclasses.fields(result)}
        assert planes and planes <= set(fields), (proto.__name__, planes - set(fields))
        for name in planes:
            assert "np.ndarray | cla.Array" in fields[name], f"{result.__name__}.{name}: {fields[name]}"
