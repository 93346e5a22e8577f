"""Ctrl-C (SIGINT) and SIGTERM stop a command with one line on stderr and
exit status 128 + the signal, and leave no temporary file in --out."""

import os
import signal
import subprocess
import sys

import pytest

CODE = "import sys; from clvis.cli import main; sys.exit(main())"


@pytest.mark.parametrize("sig,status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
@pytest.mark.parametrize("after", ["uploading", "soft z"])  # mid-render; while PNGs are written
def test_signal_gives_one_line_and_no_temporary_files(tmp_path, sig, status, after):
    out = tmp_path / "out"
    p = subprocess.Popen(
        [sys.executable, "-c", CODE, "render", "--points", "300000", "--out", str(out), "--progress"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    lines = []
    for line in p.stderr:
        lines.append(line)
        if after in line:
            p.send_signal(sig)
            break
    rest = p.stderr.read()
    p.wait(timeout=120)
    lines += rest.splitlines(keepends=True)
    assert p.returncode == status, "".join(lines)
    word = "interrupted" if sig == signal.SIGINT else "terminated"
    # the one line; before it, --progress may close the step it was in ("... failed")
    tail = rest.strip().splitlines()
    assert tail[-1] == f"clvis render: {word}", rest
    assert all(t.startswith("clvis render: ") and "failed" in t for t in tail[:-1]), rest
    left = [f for f in os.listdir(out)] if out.is_dir() else []
    assert not [f for f in left if f.endswith(".tmp")], left
