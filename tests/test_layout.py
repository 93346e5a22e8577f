"""The family rule of DESIGN.md, checked on the source (no imports run):

- every kernels_cl/<family>/<x>.cl is launched from its own family's Python
  (clvis/<family>/, or clvis/primitives.py for the primitives), and from no
  other family;
- a family never imports another family's modules: shared code lives in
  top-level clvis/*.py modules;
- the layers above the families (LAYERS: training, which renders the post
  networks' pairs with the iso and raster renderers; distributed, which runs
  the raster and iso renderers on Dask workers; view, the browser viewer; the
  command line on top) may use every family; no family, reference or top-level module imports them, and
  distributed does not import the command line;
- the library never imports clvis.reference (only the command line does, for
  the demo's checks against the references), and a family's references never
  import another family's references;
- no module takes a private ``_name`` from a module of another package, nor
  anything from another package's private module (a check another package
  needs is public where it belongs; SHARED_PRIVATE_MODULES are shared on
  purpose).
"""

import ast
import re
from pathlib import Path

import pytest

import clvis
from clvis import runtime

PACKAGE = Path(clvis.__file__).parent
FAMILIES = ("raster", "iso", "gauss", "post")
# packages that sit on top of the families and may import them, lowest first:
# each may import the ones before it (training drives the iso and raster
# renderers to make its pairs; the command line drives training and distributed)
LAYERS = ("training", "distributed", "view", "cli")
# the one import of a layer from below: the public API's clvis.view(obj), made
# when first used (clvis/__init__.py's __getattr__)
PUBLIC_LAYER_IMPORTS = {("clvis/__init__.py", "clvis.view")}


def _modules(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*.py") if "__pycache__" not in p.parts)


def _dotted(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    """The absolute names of the modules `path` imports (relative imports resolved)."""
    package = _dotted(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.add(mod)
            out.update(f"{mod}.{a.name}" for a in node.names)
    return out


def _family(module: str, root: str = "clvis") -> str | None:
    parts = module.split(".")
    if len(parts) >= 2 and parts[0] == "clvis":
        if root == "clvis.reference" and len(parts) >= 3 and parts[1] == "reference":
            return parts[2] if parts[2] in FAMILIES else None
        if root == "clvis" and parts[1] in FAMILIES:
            return parts[1]
    return None


def _kernel_files() -> list[str]:
    return sorted(
        str(p.relative_to(runtime.KERNEL_ROOT))
        for p in runtime.KERNEL_ROOT.glob("*/*.cl")
        if p.parent.name != "include"
    )


def test_layout_found_the_tree():
    kernels = _kernel_files()
    assert len(kernels) >= 19 and {k.split("/")[0] for k in kernels} == {"primitives", *FAMILIES}
    assert all((PACKAGE / f).is_dir() for f in FAMILIES)
    assert all((PACKAGE / "reference" / f).is_dir() for f in FAMILIES)


@pytest.mark.parametrize("kernel", _kernel_files())
def test_kernel_launched_from_its_family(kernel):
    family = kernel.split("/")[0]
    own = [PACKAGE / "primitives.py"] if family == "primitives" else _modules(PACKAGE / family)
    users = [p for p in _modules(PACKAGE) if f'"{kernel}"' in p.read_text()]
    assert any(p in own for p in users), f"{kernel} is not launched from clvis/{family}"
    strangers = [str(p.relative_to(PACKAGE)) for p in users if p not in own]
    assert not strangers, f"{kernel} is launched from outside its family: {strangers}"


def _design_exceptions() -> dict[str, str]:
    """DESIGN.md's list of the exceptions to one kernel file, one launcher of
    the same name: launcher path (clvis/...) -> its bullet's text."""
    text = (PACKAGE.parent / "DESIGN.md").read_text(encoding="utf-8")
    section = text.split("one launcher of the same name, and why they remain:", 1)[1].split("\n## ", 1)[0]
    return {m[0]: m[1] for m in re.findall(r"^- `(clvis/[\w/]+\.py)`(.*?)(?=^- |\Z)", section, re.M | re.S)}


@pytest.mark.parametrize("kernel", _kernel_files())
def test_other_launchers_are_listed_in_design(kernel):
    """A kernel file launched from a module of another name is in DESIGN.md's
    list of exceptions, under that module, with its reason (the primitives'
    files: clvis/primitives.py, the family's one module)."""
    family, name = kernel.split("/")
    exceptions = _design_exceptions()
    assert "clvis/primitives.py" in exceptions and "clvis/raster/render.py" in exceptions
    for path in _modules(PACKAGE):
        if f'"{kernel}"' not in path.read_text() or path.stem == name.removesuffix(".cl"):
            continue
        rel = str(path.relative_to(PACKAGE.parent))
        if family == "primitives" and rel == "clvis/primitives.py":
            continue
        assert rel in exceptions, f"{rel} launches {kernel}: DESIGN.md's list of exceptions does not name it"
        assert re.search(rf"\b{re.escape(name)}", exceptions[rel]), (
            f"{rel} launches {kernel}: its entry in DESIGN.md's list of exceptions does not name {name}"
        )


def test_no_family_imports_another():
    for family in FAMILIES:
        for path in _modules(PACKAGE / family):
            others = {m for m in _imports(path) if _family(m) not in (None, family)}
            assert not others, f"{path.relative_to(PACKAGE)} imports {sorted(others)}"


def _layer(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) >= 2 and parts[0] == "clvis" and parts[1] in LAYERS else None


def test_layers_are_packages_beside_the_families():
    assert not set(LAYERS) & set(FAMILIES)
    assert all((PACKAGE / layer / "__init__.py").is_file() for layer in LAYERS)
    # distributed has NumPy references (its compositing) like a family
    assert (PACKAGE / "reference" / "distributed").is_dir()


def test_nothing_below_a_layer_imports_it():
    """Families, their references and the top-level modules never import
    training, distributed or cli; distributed never imports cli. (clvis/__main__.py,
    `python -m clvis`, is the command line's entry point.)"""
    for path in _modules(PACKAGE):
        if path == PACKAGE / "__main__.py":
            continue
        own = _layer(_dotted(path))
        allowed = LAYERS[: LAYERS.index(own) + 1] if own else ()
        bad = {m for m in _imports(path) if _layer(m) is not None and _layer(m) not in allowed}
        bad -= {m for f, m in PUBLIC_LAYER_IMPORTS if path == PACKAGE.parent / f}
        assert not bad, f"{path.relative_to(PACKAGE)} imports {sorted(bad)}"


def test_library_never_imports_the_references():
    cli, reference = PACKAGE / "cli", PACKAGE / "reference"
    for path in _modules(PACKAGE):
        if cli in path.parents or reference in path.parents:
            continue
        bad = {m for m in _imports(path) if m == "clvis.reference" or m.startswith("clvis.reference.")}
        assert not bad, f"{path.relative_to(PACKAGE)} imports {sorted(bad)}"


def test_references_keep_to_their_family():
    for family in FAMILIES:
        for path in _modules(PACKAGE / "reference" / family):
            imports = _imports(path)
            others = {m for m in imports if _family(m, "clvis.reference") not in (None, family)}
            assert not others, f"{path.relative_to(PACKAGE)} imports {sorted(others)}"


def test_import_resolution():
    """The checker itself: relative imports are resolved against the module's package."""
    got = _imports(PACKAGE / "iso" / "render.py")
    assert "clvis.iso.cache" in got and "clvis.runtime" in got and "clvis.camera.ray_buffer" in got
    assert _family("clvis.gauss.render") == "gauss" and _family("clvis.camera") is None
    assert _family("clvis.reference.iso.zfp", "clvis.reference") == "iso"
    assert _layer("clvis.distributed.raster") == "distributed" and _layer("clvis.raster.render") is None
    assert _layer("clvis.cli._common") == "cli"
    got = _imports(PACKAGE / "distributed" / "raster.py")
    assert "clvis.raster" in got and "clvis.distributed.composite" in got


# --------------------------------------------------------------------------
# no private reach across packages


def _package_of(module: str) -> str:
    """The package a module belongs to: itself for a package, else its parent."""
    parts = module.split(".")
    path = PACKAGE.parent.joinpath(*parts)
    return module if path.is_dir() else ".".join(parts[:-1])


def _is_module(module: str) -> bool:
    path = PACKAGE.parent.joinpath(*module.split("."))
    return path.is_dir() or path.with_suffix(".py").is_file()


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


# the library's own private helper modules, shared by every package by design
# (DESIGN.md: "_arrays.py: argument checks shared by every family"; "_keys.py:
# keys.h's float32 depth key and its inverse on the host")
SHARED_PRIVATE_MODULES = {"clvis._arrays", "clvis._keys", "clvis._version"}


def _private_module(module: str) -> bool:
    """A module with a private part in its dotted name (clvis.cli._common)."""
    return any(_private(part) for part in module.split(".")[1:])


def private_reach(source: str, module: str, is_package: bool = False) -> list[str]:
    """Each `_name` the module `module` (dotted; `source` its text) takes from
    a module of another package: ``from x import _name`` and ``x._name``
    after ``import x`` / ``from p import x``; and anything taken from a
    private module of another package (``from clvis.cli._common import
    size``, ``import clvis.cli._common``). A private module shared on
    purpose (SHARED_PRIVATE_MODULES) may be imported, not its `_names`."""
    base_parts = module.split(".") if is_package else module.split(".")[:-1]
    own = ".".join(base_parts)
    bad = []
    aliases: dict[str, str] = {}  # local name -> module it is bound to
    tree = ast.parse(source)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if (
                    a.name.startswith("clvis.")
                    and _private_module(a.name)
                    and a.name not in SHARED_PRIVATE_MODULES
                    and _package_of(a.name) != own
                ):
                    bad.append(f"{module}:{node.lineno} imports the private module {a.name}")
                if a.asname:
                    aliases[a.asname] = a.name
                else:
                    aliases[a.name.split(".")[0]] = a.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = base_parts[: len(base_parts) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if not mod.startswith("clvis"):
                continue
            if _private_module(mod) and mod not in SHARED_PRIVATE_MODULES and _package_of(mod) != own:
                bad.append(f"{module}:{node.lineno} imports from the private module {mod}")
                continue
            for a in node.names:
                full = f"{mod}.{a.name}"
                if _is_module(full):  # a module: its package is where it lives
                    aliases[a.asname or a.name] = full
                    if _private(a.name) and full not in SHARED_PRIVATE_MODULES and _package_of(full) != own:
                        bad.append(f"{module}:{node.lineno} imports the private module {full}")
                elif _private(a.name) and _package_of(mod) != own:
                    bad.append(f"{module}:{node.lineno} imports {a.name} from {mod}")
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and _private(node.attr):
            target = aliases.get(node.value.id)
            if target and target.startswith("clvis") and _package_of(target) != own:
                bad.append(f"{module}:{node.lineno} reaches {target}.{node.attr}")
    return bad


def test_no_private_reach_across_packages():
    found = []
    for path in _modules(PACKAGE):
        found += private_reach(path.read_text(), _dotted(path), path.name == "__init__.py")
    assert not found, "private names taken from another package:\n" + "\n".join(found)


def test_private_reach_checker_catches_violations():
    """The checker itself, on sources that break the rule (and some that do not)."""
    bad = """
from ..raster.render import _batch_bounds, EMPTY
from .. import volumes_missing
from ..io import volumes
from clvis.camera import _vec3
import clvis.runtime.settings as st
volumes._index(3)
st._in_force()
"""
    found = private_reach(bad, "clvis.distributed.fake")
    assert len(found) == 4, found
    assert "imports _batch_bounds from clvis.raster.render" in found[0]
    assert any("imports _vec3 from clvis.camera" in f for f in found)
    assert any("reaches clvis.io.volumes._index" in f for f in found)
    assert any("reaches clvis.runtime.settings._in_force" in f for f in found)
    # the same names inside their own package are fine, and so is the shared _arrays
    assert private_reach("from .render import _batch_bounds\n", "clvis.raster.morton") == []
    assert private_reach("from .settings import _in_force\n", "clvis.runtime.device") == []
    assert private_reach("from .._arrays import check_array\n", "clvis.raster.render") == []
    assert private_reach("from .. import _arrays\n", "clvis.gauss.fake") == []
    assert private_reach("from ..cli import _common\n", "clvis.training.fake") != []
    # public names of another package's private module, by either import form
    assert private_reach("from ..cli._common import size\n", "clvis.training.fake") == [
        "clvis.training.fake:1 imports from the private module clvis.cli._common"
    ]
    assert private_reach("import clvis.cli._common as c\n", "clvis.distributed.fake") == [
        "clvis.distributed.fake:1 imports the private module clvis.cli._common"
    ]
    assert private_reach("from ._common import size\n", "clvis.cli.raster") == []
    assert private_reach("from .._keys import key_f32\n", "clvis.gauss.bvh") == []  # shared on purpose
