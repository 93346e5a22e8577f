#!/usr/bin/env bash
# The project's commands. Each makes (or refreshes) its own virtual environment,
# so a fresh machine needs only python3.
#
#   ./dev.sh demo    .venv: clvis + PoCL; runs `clvis demo`
#   ./dev.sh test [PATHS] [PYTEST ARGS]
#                    .venv-test: clvis + PoCL + Intel's CPU OpenCL runtime (x86-64
#                    Linux) + test tools; runs the tests on every OpenCL device
#                    found (2^27-element cases included), then the benchmark
#                    suites once each at a tiny scale; with test paths
#                    (tests/iso, tests/x.py::case) only those
#   ./dev.sh bench [FAMILY]
#                    .venv-test; runs `clvis bench FAMILY` (full sizes) for
#                    every family, or the family named
#   ./dev.sh oclgrind [ARGS]
#                    .venv-test; every kernel at small sizes under the Oclgrind
#                    simulator (apt-get install oclgrind), both work shapes, 64-bit
#                    atomics on and off; fails on invalid accesses and on data
#                    races not marked benign in the kernel source
#                    (tests/oclgrind/audit.py; ARGS go to it; ~2 min)
#   ./dev.sh fuzz [--minutes N | --cases N] [--seed S]
#                    .venv-test; mutation fuzzing of every reader
#                    (tests/fuzz/run.py), each case in a forked child under a
#                    4 GiB address-space limit and a timeout; fails on a crash,
#                    hang, foreign exception or a peak RSS over 256 MB for a
#                    file under 1 MB (default: 5 minutes)
#   ./dev.sh lint    .venv-lint: ruff (lint + format check) on the whole tree and
#                    mypy on the whole package
#   ./dev.sh fmt     .venv-lint: ruff format + ruff check --fix
#
# Extra arguments go to the command (pytest, clvis demo, clvis bench, the audit).
set -euo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python3}

venv() { # venv DIR EXTRAS
    # pip runs only when the venv is new, pyproject.toml changed or an extra is
    # new to it (.clvis-installed: the pyproject.toml hash, then the extras
    # installed); the package is installed editable, so code changes need none
    local stamp="$1/.clvis-installed" hash have="" e missing=
    [ -x "$1/bin/python" ] || "$PY" -m venv "$1"
    hash=$(sha256sum pyproject.toml | cut -d' ' -f1)
    if [ -f "$stamp" ] && [ "$(sed -n 1p "$stamp")" = "$hash" ]; then
        have=$(sed -n 2p "$stamp")
    fi
    for e in ${2//,/ }; do
        case ",$have," in *",$e,"*) ;; *) missing=1 ;; esac
    done
    [ -n "$missing" ] || return 0
    rm -f "$stamp"
    "$1/bin/python" -m pip install -q --disable-pip-version-check --upgrade pip
    "$1/bin/python" -m pip install -q --disable-pip-version-check -e ".[$2]"
    printf '%s\n%s\n' "$hash" "${have:+$have,}$2" > "$stamp"
}

with_intel() { # Intel's runtime only ships for x86-64 Linux
    [ "$(uname -s)" = Linux ] && [ "$(uname -m)" = x86_64 ]
}

intel_env() { # VENV: point the ICD loader at Intel's runtime inside the venv
    local lib
    lib=$(ls "$PWD/$1"/lib/libintelocl.so 2>/dev/null || true)
    [ -n "$lib" ] || { echo "dev.sh: intel-opencl-rt is not in $1" >&2; return 1; }
    mkdir -p "$1/etc/clvis-icd"
    echo "$lib" > "$1/etc/clvis-icd/intel.icd"
    # pyopencl's bundled loader reads this folder and still finds its own PoCL
    export OCL_ICD_VENDORS="$PWD/$1/etc/clvis-icd"
    # libintelocl.so finds its compiler runtime (libimf, libsvml, tbb) here
    export LD_LIBRARY_PATH="$PWD/$1/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
}

# mypy's scope: the whole package, one path a line (tests/test_typing.py
# fails when a module of clvis is left out, so a new module is typed from the
# start; no module-wide ignores, a per-line ignore only where a third-party
# stub forces it)
TYPED="
    clvis
"

cmd=${1:-}
shift || true
case "$cmd" in
lint)
    venv .venv-lint lint
    .venv-lint/bin/ruff check clvis tests bench
    .venv-lint/bin/ruff format --check clvis tests bench
    # shellcheck disable=SC2086
    exec .venv-lint/bin/mypy $TYPED
    ;;
fmt)
    venv .venv-lint lint
    .venv-lint/bin/ruff format clvis tests bench
    exec .venv-lint/bin/ruff check --fix clvis tests bench
    ;;
demo)
    venv .venv pocl
    exec .venv/bin/clvis demo "$@"
    ;;
test | bench)
    if with_intel; then
        venv .venv-test pocl,test,intel,train,distributed,view
        intel_env .venv-test
        export CLVIS_REQUIRE_PLATFORMS=${CLVIS_REQUIRE_PLATFORMS:-portable,intel}
    else
        venv .venv-test pocl,test,train,distributed,view
        export CLVIS_REQUIRE_PLATFORMS=${CLVIS_REQUIRE_PLATFORMS:-portable}
    fi
    if [ "$cmd" = bench ]; then
        case "${1:-}" in
        primitives | raster | gauss | iso | post | distributed | view)
            exec .venv-test/bin/clvis bench "$@"
            ;;
        esac
        .venv-test/bin/clvis bench primitives "$@"
        .venv-test/bin/clvis bench raster "$@"
        .venv-test/bin/clvis bench gauss "$@"
        .venv-test/bin/clvis bench iso "$@"
        .venv-test/bin/clvis bench post "$@"
        .venv-test/bin/clvis bench distributed "$@"
        exec .venv-test/bin/clvis bench view "$@"
    fi
    # CLVIS_LARGE=1: the 2^27-element tests too (~1.5 min, ~8 GB)
    export CLVIS_LARGE=${CLVIS_LARGE:-1} CLVIS_BENCH_SCALE=${CLVIS_BENCH_SCALE:-0.001}
    # arguments that name test paths (tests/iso, tests/x.py::name) select what runs;
    # other arguments (-k, -x, -m ...) apply to the whole suite
    selected=
    for a in "$@"; do
        case "$a" in -*) ;; *) [ -e "${a%%::*}" ] && selected=1 ;; esac
    done
    if [ -n "$selected" ]; then
        exec .venv-test/bin/python -m pytest --benchmark-disable -q "$@"
    fi
    exec .venv-test/bin/python -m pytest tests bench --benchmark-disable -q "$@"
    ;;
fuzz)
    venv .venv-test pocl,test,train,distributed
    exec .venv-test/bin/python -W ignore tests/fuzz/run.py "$@"
    ;;
oclgrind)
    if with_intel; then
        venv .venv-test pocl,test,intel,train,distributed
    else
        venv .venv-test pocl,test,train,distributed
    fi
    # Oclgrind's preloaded runtime replaces every ICD: no intel_env here
    exec .venv-test/bin/python tests/oclgrind/audit.py "$@"
    ;;
*)
    echo "usage: ./dev.sh demo | test | bench | oclgrind | fuzz | lint | fmt  [args]" >&2
    exit 2
    ;;
esac
