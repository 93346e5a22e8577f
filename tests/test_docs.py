"""Docs that cannot rot: every repository path named in the Markdown files,
in the comments of the OpenCL sources and in the Python docstrings exists,
every dotted ``clvis.<module>...`` name in them resolves, and ``clvis --help`` lists
every command and every choice of their positional arguments."""

import ast
import importlib
import io
import re
from contextlib import redirect_stdout
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# a path into the tree: clvis/..., kernels_cl/..., tests/... (not inside a longer
# path or word; up to the last letter or digit, so "...py)." ends at "py"). A
# placeholder is left out: a name with <...> in it (kernels_cl/<family>/<x>.cl
# is checked up to kernels_cl, tests/test_<x>.py not at all) or in capitals
# (models/NAME.onnx)
PATH = re.compile(r"(?<![\w/.\-])((?:clvis|kernels_cl|tests)/[\w./\-]*\w)(?![\w<])")
PLACEHOLDER = re.compile(r"(^|/)[A-Z][A-Z_]*(\.|/|$)")
# a dotted name of the package: clvis.runtime.configure, clvis.io.volumes
DOTTED = re.compile(r"(?<![\w/.\-])(clvis(?:\.[A-Za-z_]\w*)+)")


def _markdown() -> list[Path]:
    return sorted(
        p for p in ROOT.rglob("*.md") if not any(part.startswith(".") for part in p.relative_to(ROOT).parts)
    )


def _kernel_comments() -> dict[Path, str]:
    out = {}
    for p in sorted((ROOT / "kernels_cl").rglob("*")):
        if p.suffix in (".cl", ".h"):
            text = p.read_text(encoding="utf-8")
            out[p] = "\n".join(re.findall(r"/\*.*?\*/|//[^\n]*", text, re.S))
    return out


def _docstrings(path: Path) -> str:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docs = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                docs.append(doc)
    return "\n".join(docs)


def _python() -> list[Path]:
    return sorted(
        p
        for d in ("clvis", "tests", "bench")
        for p in (ROOT / d).rglob("*.py")
        if "__pycache__" not in p.parts
    )


def _sources() -> dict[str, str]:
    """name -> the text whose paths must exist."""
    texts = {str(p.relative_to(ROOT)): p.read_text(encoding="utf-8") for p in _markdown()}
    texts.update({str(p.relative_to(ROOT)): t for p, t in _kernel_comments().items()})
    texts.update({str(p.relative_to(ROOT)): _docstrings(p) for p in _python()})
    return texts


def _exists(path: str) -> bool:
    if (ROOT / path).exists():
        return True
    # "clvis/camera.h": an OpenCL include, relative to kernels_cl/include
    return (
        path.startswith("clvis/")
        and path.endswith(".h")
        and (ROOT / "kernels_cl" / "include" / path).exists()
    )


def _resolves(name: str) -> bool:
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def stale_paths(texts: dict[str, str]) -> list[str]:
    return [
        f"{name}: {m}"
        for name, text in texts.items()
        for m in sorted(set(PATH.findall(text)))
        if not PLACEHOLDER.search(m) and not _exists(m)
    ]


def stale_names(texts: dict[str, str]) -> list[str]:
    return [
        f"{name}: {m}"
        for name, text in texts.items()
        for m in sorted(set(DOTTED.findall(text)))
        if not _resolves(m)
    ]


def test_sources_found():
    texts = _sources()
    assert "README.md" in texts and "DESIGN.md" in texts and "kernels_cl/iso/traverse.cl" in texts
    assert "clvis/runtime/__init__.py" in texts and "tests/test_docs.py" in texts
    assert sum(len(PATH.findall(t)) for t in texts.values()) > 200


def test_named_paths_exist():
    bad = stale_paths(_sources())
    assert not bad, f"{len(bad)} paths named in the docs do not exist:\n" + "\n".join(bad)


def test_dotted_names_resolve():
    bad = stale_names(_sources())
    assert not bad, f"{len(bad)} clvis.* names in the docs do not resolve:\n" + "\n".join(bad)


def test_checkers_find_stale_text():
    """The checkers themselves, on text naming things that are gone (and some that are not)."""
    fake = {
        "a.md": "see clvis/reference/iso.py and `kernels_cl/iso/traverse.cl`, "
        "kernels_cl/include/clvis/ray.h, clvis/ray.h and kernels_cl/<family>/<x>.cl, "
        "tests/test_<module>.py, clvis/post/models/NAME.onnx, clvis/post/models/nothing.onnx.",
        "b.cl": "/* the rules of clvis/reference/iso_traverse.py */",
    }
    assert stale_paths(fake) == [
        "a.md: clvis/post/models/nothing.onnx",
        "a.md: clvis/reference/iso.py",
        "b.cl: clvis/reference/iso_traverse.py",
    ]
    names = {
        "c.py": "clvis.post.data, clvis.io.volumes.read_volume, clvis.zfp.ZfpVolume, clvis.volumes.nothing"
    }
    assert stale_names(names) == ["c.py: clvis.post.data", "c.py: clvis.volumes.nothing"]


# --------------------------------------------------------------------------
# clvis --help


def _help(*argv: str) -> str:
    from clvis import cli

    out = io.StringIO()
    with redirect_stdout(out):
        assert cli.main([*argv, "--help"]) == 0
    return out.getvalue()


def test_help_lists_every_command_and_choice():
    from clvis import cli

    top = _help()
    _, commands = cli._parser()
    assert set(commands) == set(cli._COMMANDS)
    for name, parser in commands.items():
        assert re.search(rf"^clvis {name}\b", top, re.M), f"clvis --help does not list `clvis {name}`"
        own = _help(name)
        for action in parser._actions:
            if not action.choices:
                continue
            for choice in action.choices:
                assert str(choice) in own, f"clvis {name} --help does not list {choice!r}"
                if not action.option_strings:  # a positional argument: the top help lists it too
                    line = re.search(rf"^clvis {name} (.*)$", top, re.M)
                    assert line and str(choice) in line.group(1).split("|"), (
                        f"clvis --help does not list `clvis {name} {choice}`"
                    )


@pytest.mark.parametrize("name", ["bench", "train"])
def test_help_checker_would_see_a_missing_choice(name):
    """The top help's command lines carry the choices (not a hand-written list)."""
    from clvis import cli

    _, commands = cli._parser()
    positional = [a for a in commands[name]._actions if a.choices and not a.option_strings]
    assert positional
    line = re.search(rf"^clvis {name} (.*)$", _help(), re.M)
    assert line and line.group(1).split("|") == list(positional[0].choices)


# --------------------------------------------------------------------------
# the README's layout block


def _layout_block() -> dict[str, str]:
    """folder -> the text of its lines in the README's layout block."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = text.split("## Layout", 1)[1].split("```", 2)[1]
    out: dict[str, str] = {}
    key = None
    for line in block.splitlines():
        if line[:1] not in (" ", ""):
            key = line.split()[0]
            out[key] = line[len(key) :]
        elif key:
            out[key] += " " + line.strip()
    return out


def test_readme_layout_names_every_kernel_and_module():
    block = _layout_block()
    for folder in sorted((ROOT / "kernels_cl").iterdir()):
        if folder.name == "include":
            continue
        line = block.get(f"kernels_cl/{folder.name}/")
        assert line is not None, f"the README's layout has no kernels_cl/{folder.name}/ line"
        for cl in sorted(folder.glob("*.cl")):
            assert re.search(rf"\b{cl.stem}\b", line), (
                f"the README's layout does not name {cl.relative_to(ROOT)}"
            )
    # the public top-level modules, on the lines of top-level files (clvis/camera.py colormap.py ...)
    files = " ".join(f"{key} {line}" for key, line in block.items() if re.fullmatch(r"clvis/\w+\.py", key))
    for mod in sorted((ROOT / "clvis").glob("*.py")):
        if not mod.name.startswith("_"):
            assert re.search(rf"(^|[\s/]){re.escape(mod.name)}", files), (
                f"the README's layout does not name {mod.relative_to(ROOT)}"
            )
    for pkg in ("runtime", "io", "raster", "iso", "gauss", "post", "training", "distributed", "view"):
        line = block.get(f"clvis/{pkg}/")
        assert line is not None, f"the README's layout has no clvis/{pkg}/ line"
        for mod in sorted((ROOT / "clvis" / pkg).glob("*.py")):
            if mod.name != "__init__.py":
                assert f"{mod.name}" in line, f"the README's layout does not name {mod.relative_to(ROOT)}"


def _design_block() -> str:
    text = (ROOT / "DESIGN.md").read_text(encoding="utf-8")
    return text.split("## Layout: one rule", 1)[1].split("```", 4)[3]


def _design_entries() -> dict[str, str]:
    """The DESIGN layout block's top-level entries: first word -> its text
    (the entry's line and the indented lines under it)."""
    out: dict[str, str] = {}
    key = None
    for line in _design_block().splitlines():
        if line[:1] not in (" ", ""):
            key = line.split()[0]
            out[key] = line
        elif key:
            out[key] += "\n" + line
    return out


def _folders(root: Path) -> list[str]:
    """The folders of `root`, less the hidden ones and build outputs."""
    return sorted(
        p.name
        for p in root.iterdir()
        if p.is_dir()
        and not p.name.startswith((".", "_"))
        and not p.name.endswith(".egg-info")
        and p.name not in ("build", "dist")
    )


def test_design_layout_names_every_folder_and_bench_script():
    """The repository's folders, tests/'s folders and bench/'s scripts are in
    DESIGN.md's layout block."""
    entries = _design_entries()
    assert {"kernels_cl/", "clvis/", "bench/", "tests/"} <= set(entries)
    missing = [f"{name}/" for name in _folders(ROOT) if f"{name}/" not in entries]
    tests = entries["tests/"]
    families = {"primitives", "raster", "iso", "gauss", "post"}  # <family>/test_<x>.py
    missing += [f"tests/{n}/" for n in _folders(ROOT / "tests") if n not in families and f"{n}/" not in tests]
    missing += [
        f"bench/{p.name}"
        for p in sorted((ROOT / "bench").glob("*.py"))
        if p.name not in entries["bench/"]
        and not re.fullmatch(r"bench_(primitives|raster|iso|gauss|post)\.py", p.name)
    ]
    assert not missing, f"DESIGN.md's layout does not name: {missing}"


def test_design_layout_names_every_module():
    block = _design_block()
    package = ROOT / "clvis"
    missing = [
        p.name
        for p in package.glob("*.py")
        if p.name not in block and p.name not in ("__main__.py", "_version.py")
    ]
    for d in sorted(p for p in package.iterdir() if p.is_dir() and (p / "__init__.py").is_file()):
        if f"{d.name}/" not in block:
            missing.append(f"{d.name}/")
        elif d.name != "reference":  # the references mirror the tree: named as folders
            missing += [
                f"{d.name}/{m.name}"
                for m in d.glob("*.py")
                if m.stem not in block and m.name != "__main__.py"
            ]
    assert not missing, f"DESIGN.md's layout does not name: {sorted(missing)}"
