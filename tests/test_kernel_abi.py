"""The ABI comment at the top of every kernels_cl/<family>/<x>.cl agrees with
the kernels below it: each ``kernel name(...)`` line there lists the kernel's
arguments in the signature's order, by the signature's names, and where it
gives a type, the signature's type (address space, base type, pointer; const,
restrict and volatile aside). An application that lifts a .cl file binds its
arguments from that comment alone (README.md, "Embedding the kernels").

Shorthands the comments use, and how they are checked:

- ``kernel k(the arguments of j)``: k's signature is j's, exactly;
- ``kernel k(... same arguments ..., global uint *vis, drawn, walk)`` or
  ``kernel k(same, ...)``: the arguments written out after the shorthand are
  the signature's last ones, in order;
- a name without a type (``recs, uint n, proj, ...``): the name and its place
  only (its type is given elsewhere in the comment);
- words two or more spaces after an argument's comma, to the end of the line
  (``uint n,   n x 3``), are a note and skipped.

And the rest a build from the comment needs: the comment names
-cl-fp32-correctly-rounded-divide-sqrt where the library builds the file with
it, -I kernels_cl/include and each clvis/ header the file includes; every
repository path the kernel comments name exists; each define a comment lists
is read; CLVIS_INT64_ATOMICS, which files built together must read alike, is
tested for definedness only.
"""

import re
from pathlib import Path

import pytest

import clvis
from clvis import runtime

QUALIFIERS = {"const", "restrict", "__restrict", "volatile"}
ADDRESS_SPACES = {"global", "local", "constant", "private"}
TYPE_WORD = re.compile(
    r"\*|global|local|constant|private|const|restrict|volatile"
    r"|(u?char|u?short|u?int|u?long|float|double|half|bool|size_t)(2|3|4|8|16)?"
    r"|clvis_\w+|T|[A-Z]+_T"
)
SHORTHAND = {"same", "..."}


def _kernel_files() -> list[Path]:
    return sorted(p for p in runtime.KERNEL_ROOT.glob("*/*.cl") if p.parent.name != "include")


def _inside_parentheses(text: str, open_at: int) -> str:
    """The text between the '(' at open_at and its matching ')'."""
    depth = 0
    for i in range(open_at, len(text)):
        if text[i] == "(":
            depth += 1
        elif text[i] == ")":
            depth -= 1
            if depth == 0:
                return text[open_at + 1 : i]
    raise AssertionError(f"unbalanced parentheses after: {text[open_at : open_at + 80]!r}")


def _type(tokens: list[str]) -> list[str]:
    return [t for t in tokens if t not in QUALIFIERS]


def signatures(code: str) -> dict[str, list[tuple[str, list[str]]]]:
    """kernel name -> [(argument name, its type tokens)] of the source's
    ``kernel ... void name(...)`` definitions (the first of a name: a kernel
    defined under #if branches takes the same arguments in each)."""
    out: dict[str, list[tuple[str, list[str]]]] = {}
    for m in re.finditer(r"^kernel\b[^;{]*?\bvoid\s+(\w+)\s*\(", code, re.M | re.S):
        args = []
        for part in _inside_parentheses(code, m.end() - 1).split(","):
            tokens = re.findall(r"\w+|\*", part)
            args.append((tokens[-1], _type(tokens[:-1])))
        out.setdefault(m[1], args)
    return out


def documented(comment: str) -> dict[str, str]:
    """kernel name -> the text between the parentheses of its ``kernel
    name(...)`` line in the ABI comment (the comment's leading '*' removed)."""
    text = re.sub(r"^[ \t]*\*", "", comment, flags=re.M)
    out: dict[str, str] = {}
    for m in re.finditer(r"\bkernel\s+(\w+)\s*\(", text):
        out.setdefault(m[1], _inside_parentheses(text, m.end() - 1))
    return out


def _documented_type(tokens: list[str], at: int) -> list[str]:
    """The type words right before tokens[at] (a name), from the address space
    on where there is one (words before it are a note on the line above)."""
    j = at
    while j > 0 and TYPE_WORD.fullmatch(tokens[j - 1]):
        j -= 1
    words = tokens[j:at]
    spaces = [i for i, t in enumerate(words) if t in ADDRESS_SPACES]
    if spaces:
        words = words[spaces[0] :]
    return _type(words)


def _check_in_order(kernel: str, args, tokens: list[str]) -> list[str]:
    errors, pos = [], 0
    for name, typ in args:
        try:
            at = tokens.index(name, pos)
        except ValueError:
            errors.append(
                f"kernel {kernel}: argument {' '.join(typ)} {name} is missing from the ABI comment "
                "or out of the signature's order there"
            )
            return errors
        doc_type = _documented_type(tokens, at)
        if doc_type and doc_type != typ[-len(doc_type) :]:
            errors.append(
                f"kernel {kernel}: argument {name} is {' '.join(typ)} in the signature, "
                f"{' '.join(doc_type)} in the ABI comment"
            )
        pos = at + 1
    return errors


def abi_errors(source: str) -> list[str]:
    """Disagreements between a .cl file's ABI comment and its kernels."""
    end = source.index("*/")
    actual, doc = signatures(source[end:]), documented(source[:end])
    errors = []
    for kernel, args in actual.items():
        if kernel not in doc:
            errors.append(f"kernel {kernel}: not in the ABI comment")
            continue
        text = doc[kernel]
        alias = re.fullmatch(r"\s*the arguments of (\w+)\s*", text)
        if alias:
            if actual.get(alias[1]) != args:
                errors.append(f"kernel {kernel}: documented as the arguments of {alias[1]}, which differ")
            continue
        # a note after an argument: two or more spaces after its comma, to the line's end
        text = re.sub(r",[ \t]{2,}[^\n]*", ",", text)
        tokens = re.findall(r"\.\.\.|\w+|\*|,", text)
        short = [i for i, t in enumerate(tokens) if t in SHORTHAND]
        if short:
            tail = tokens[short[-1] + 1 :]
            # the names written out: words followed by a comma or the end
            named = [
                t
                for i, t in enumerate(tail)
                if re.fullmatch(r"\w+", t) and tail[i + 1 : i + 2] in ([","], [])
            ]
            if not named or len(named) > len(args):
                errors.append(
                    f"kernel {kernel}: the arguments after the shorthand do not match its signature"
                )
                continue
            errors += _check_in_order(kernel, args[-len(named) :], tail)
            if [n for n, _ in args[-len(named) :]] != named:
                errors.append(
                    f"kernel {kernel}: the ABI comment ends its arguments with {named}, "
                    f"the signature with {[n for n, _ in args[-len(named) :]]}"
                )
        else:
            errors += _check_in_order(kernel, args, tokens)
    for kernel in doc:
        if kernel not in actual:
            errors.append(f"kernel {kernel}: in the ABI comment but not defined in the file")
    return errors


@pytest.mark.parametrize("path", _kernel_files(), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_abi_comment_matches_the_signatures(path):
    assert abi_errors(path.read_text(encoding="utf-8")) == []


def test_the_check_finds_what_it_should():
    """The check is not vacuous: a swapped pair, a renamed argument, a wrong
    type, a kernel left out and a stale alias are each reported."""
    good = """/* ABI
 * kernel k(global const float *in, uint n,   n x 3
 *          global uint *out)
 * kernel k8(the arguments of k)
 * kernel j(... same arguments ..., global uint *out)
 */
kernel void k(global const float *restrict in, const uint n, global uint *out) {}
kernel void k8(global const float *in, uint n, global uint *out) {}
kernel void j(global const float *in, uint n, global uint *out) {}
"""
    assert abi_errors(good) == []
    bad = {
        "swapped": good.replace("global const float *in, uint n,", "uint n, global const float *in,"),
        "renamed": good.replace("uint n,   n x 3", "uint count,   n x 3"),
        "type": good.replace("global uint *out)\n * kernel k8", "global int *out)\n * kernel k8"),
        "space": good.replace("global const float *in, uint n,  ", "local const float *in, uint n,  "),
        "missing": good.replace(" * kernel j(... same arguments ..., global uint *out)\n", ""),
        "alias": good.replace("k8(global const float *in, uint n,", "k8(global const float *in, ulong n,"),
        "tail": good.replace("arguments ..., global uint *out)", "arguments ..., global uint *res)"),
        "stale": good.replace(" */\n", " * kernel gone(uint n)\n */\n"),
    }
    for what, source in bad.items():
        assert abi_errors(source), what


def _exact_fp_builds() -> set[str]:
    """The kernels_cl files the library builds with runtime.EXACT_FP (its
    get_kernel / get_program calls: the file a string or a module-level name,
    the flags runtime.EXACT_FP or a name assigned from it)."""
    import ast

    package = Path(clvis.__file__).parent
    out = set()
    for module in package.rglob("*.py"):
        tree = ast.parse(module.read_text(encoding="utf-8"))
        strings = {
            t.id: node.value.value
            for node in ast.walk(tree)
            if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant)
            for t in node.targets
            if isinstance(t, ast.Name) and isinstance(node.value.value, str)
        }
        exact = {
            t.id
            for node in ast.walk(tree)
            if isinstance(node, ast.Assign)
            and isinstance(node.value, ast.Attribute)
            and node.value.attr == "EXACT_FP"
            for t in node.targets
            if isinstance(t, ast.Name)
        }
        for call in ast.walk(tree):
            if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Attribute)):
                continue
            if call.func.attr not in ("get_kernel", "get_program") or len(call.args) < 2:
                continue
            flags = call.args[4] if call.func.attr == "get_kernel" and len(call.args) > 4 else None
            if call.func.attr == "get_program" and len(call.args) > 3:
                flags = call.args[3]
            flags = next((k.value for k in call.keywords if k.arg == "flags"), flags)
            is_exact = (isinstance(flags, ast.Attribute) and flags.attr == "EXACT_FP") or (
                isinstance(flags, ast.Name) and flags.id in exact
            )
            src = call.args[1]
            rel = src.value if isinstance(src, ast.Constant) else strings.get(getattr(src, "id", ""))
            if is_exact and isinstance(rel, str) and rel.endswith(".cl"):
                out.add(rel)
    return out


def test_exact_fp_builds_are_named_in_the_abi_comment():
    """A file the library builds with -cl-fp32-correctly-rounded-divide-sqrt
    says so in its ABI comment: an application that builds it from the
    comment alone gets the same bits."""
    built = _exact_fp_builds()
    assert {"post/pushpull.cl", "gauss/tiles.cl", "raster/resolve.cl"} <= built  # the scan finds them
    flag = "-cl-fp32-correctly-rounded-divide-sqrt"
    comments = {rel: (runtime.KERNEL_ROOT / rel).read_text().split("*/")[0] for rel in sorted(built)}
    missing = [rel for rel, comment in comments.items() if flag not in comment]
    assert missing == [], f"built with runtime.EXACT_FP, the ABI comment does not say so: {missing}"


@pytest.mark.parametrize("path", _kernel_files(), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_includes_are_named_in_the_abi_comment(path):
    """A file that includes clvis/ headers names the include path (as a
    compiler option) and each header it includes in its ABI comment."""
    source = path.read_text(encoding="utf-8")
    headers = sorted(set(re.findall(r'^#include "(clvis/\w+\.h)"', source, re.M)))
    comment = source[: source.index("*/")]
    if headers:
        assert "-I kernels_cl/include" in comment, "the ABI comment does not name -I kernels_cl/include"
    assert [h for h in headers if h not in comment] == [], "headers the ABI comment does not name"


def test_paths_named_in_kernel_comments_exist():
    """Every repository path a kernel file or shared header names (a reference,
    a test, a benchmark, another kernel) exists: the comments send an
    embedder there for the definitions."""
    root = runtime.KERNEL_ROOT.parent
    files = _kernel_files() + sorted((runtime.KERNEL_ROOT / "include" / "clvis").glob("*.h"))
    missing, named = [], 0
    for path in files:
        text = re.sub(r"/\n\s*\*\s*", "/", path.read_text(encoding="utf-8"))  # a path wrapped after a '/'
        for m in re.finditer(r"(?<![\w/.])((?:clvis|kernels_cl|tests|bench|docs)/[\w./-]*\w)", text):
            rel, named = m[1], named + 1
            if not (root / rel).exists() and not (runtime.KERNEL_ROOT / "include" / rel).exists():
                missing.append(f"{path.relative_to(root)}: {rel}")
    assert named > 50  # the scan finds the comments' paths
    assert missing == []


def test_int64_atomics_define_is_tested_by_definedness_everywhere():
    """CLVIS_INT64_ATOMICS means one thing in every file: defined or not
    (#ifdef, defined(...)), never its value. iso/pass.cl and iso/raytrace.cl
    work as a pair: when one read the value and the other definedness, a host
    passing -DCLVIS_INT64_ATOMICS=0 got an image with no hits."""
    files = _kernel_files() + sorted((runtime.KERNEL_ROOT / "include" / "clvis").glob("*.h"))
    by_value = []
    for path in files:
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if not re.match(r"\s*#\s*(el)?if\b", line) or "CLVIS_INT64_ATOMICS" not in line:
                continue
            if re.search(r"(?<!defined\()(?<!defined )\bCLVIS_INT64_ATOMICS\b", line):
                by_value.append(f"{path.relative_to(runtime.KERNEL_ROOT)}:{number}: {line.strip()}")
    assert by_value == []


def _with_headers(source: str) -> str:
    """source and the text of every clvis/ header it includes, transitively."""
    text, seen = source, set()
    stack = re.findall(r'^#include "(clvis/\w+\.h)"', source, re.M)
    while stack:
        header = stack.pop()
        if header in seen:
            continue
        seen.add(header)
        body = (runtime.KERNEL_ROOT / "include" / header).read_text(encoding="utf-8")
        text += body
        stack += re.findall(r'^#include "(clvis/\w+\.h)"', body, re.M)
    return text


def test_documented_defines_are_read():
    """Each define an ABI comment lists as an entry (``NAME   what it does``)
    is read by the file or a header it includes: a host sets no define that
    does nothing (kpn.cl and subpixel.cl listed a WG that no line read)."""
    unread, listed = [], 0
    for path in _kernel_files():
        source = path.read_text(encoding="utf-8")
        end = source.index("*/")
        code = _with_headers(source[end:])
        for name in re.findall(r"^ \*\s{1,5}([A-Z][A-Z0-9_]*)(?:\s{2,}|\s+\d)", source[:end], re.M):
            if name == "ABI":
                continue
            listed += 1
            if not re.search(rf"\b{name}\b", code):
                unread.append(f"{path.relative_to(runtime.KERNEL_ROOT)}: {name}")
    assert listed > 30  # the scan finds the comments' define lists
    assert unread == []
