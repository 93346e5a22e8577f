"""Every bad value is one line on stderr and exit status 2, found before any
work starts; library errors likewise; --version, a bare clvis, a closed pipe."""

import io
import os
import subprocess
import sys
from pathlib import Path

import pytest

import clvis
from clvis import cli
from clvis.errors import DeviceError


def _main(capsys, *args):
    rc = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def _one_line_error(err, command):
    assert err.startswith(f"clvis {command}: error: "), err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert "Traceback" not in err


@pytest.mark.parametrize(
    "args, message",
    [
        (["gauss", "--density", "-1"], "argument --density: expected a number > 0 (finite), got '-1'"),
        (["gauss", "--density", "nan"], "argument --density: expected a number > 0 (finite), got 'nan'"),
        (["gauss", "--k", "0"], "argument --k: expected a positive integer in 1..64, got '0'"),
        (["gauss", "--density", "0"], "argument --density: expected a number > 0 (finite), got '0'"),
        (["gauss", "--threshold", "nan"], "argument --threshold: expected a number (finite), got 'nan'"),
        (["gauss", "--colormap", "nope"], "argument --colormap: unknown colormap 'nope'"),
        (["render", "--colormap", "viridiss"], "closest: viridis"),
        (["iso", "--isovalue", "nan"], "argument --isovalue: expected a number (finite), got 'nan'"),
        (["iso", "--rate", "0"], "argument --rate: expected a positive integer in 1..32"),
        (["iso", "--size", "-5x5"], "argument --size: width and height must lie in 1..32768, got '-5x5'"),
        (["gauss", "--size", "-5x5"], "argument --size: width and height must lie in 1..32768"),
        (["render", "--size", "-5x5"], "argument --size: width and height must lie in 1..32768"),
        (["gauss", "--size", "32769x2"], "argument --size: width and height must lie in 1..32768"),
        (["demo", "--n", "-5"], "argument --n: expected a positive integer in 1..4,294,967,295, got '-5'"),
        (["demo", "--iso-size", "0x4"], "argument --iso-size: width and height must lie in"),
        (
            ["render", "--points", "1e11"],
            "argument --points: expected a positive integer in 1..4,294,967,294",
        ),
        (["render", "--view", "top", "--fov", "30"], "--fov: the top view is orthographic"),
        (["iso", "--eye", "1,2"], "argument --eye: expected three finite numbers X,Y,Z"),
        (["iso", "--eye", "-1,nan,3"], "argument --eye: expected three finite numbers X,Y,Z"),
        (["gauss", "--up", "0,0,0"], "argument --up: expected a non-zero direction"),
        (["gauss", "--fov", "180"], "argument --fov: expected a field of view in degrees"),
        (["iso", "--eye", "1,1,1", "--target", "1,1,1"], "--eye and --target are the same point"),
        (["bench", "primitives", "--scale", "-1"], "argument --scale: expected a number > 0"),
    ],
)
def test_bad_values(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    loads = []
    monkeypatch.setattr(clvis.datasets, "explosion", lambda *a, **k: loads.append(1))
    monkeypatch.setattr(clvis.datasets, "marschner_lobb", lambda *a, **k: loads.append(1))
    monkeypatch.setattr(clvis.datasets, "hurricane", lambda *a, **k: loads.append(1))
    rc, out, err = _main(capsys, *args, *(["--out", tmp_path / "out"] if args[0] != "bench" else []))
    assert rc == 2 and out == ""
    _one_line_error(err, args[0])
    assert message in err, err
    assert not loads and not (tmp_path / "out").exists()  # nothing loaded, nothing written


@pytest.mark.parametrize("command", [["render", "x.ply"], ["iso"], ["gauss"], ["demo"], ["train", "infill"]])
@pytest.mark.parametrize("value", ["", "  "])
def test_an_empty_out_folder_is_refused(tmp_path, capsys, monkeypatch, command, value):
    """-o "" (an unset $OUTDIR) would write into the current folder unnoticed."""
    monkeypatch.chdir(tmp_path)
    rc, out, err = _main(capsys, *command, "--out", value)
    assert rc == 2 and out == ""
    _one_line_error(err, command[0])
    assert f"argument --out: expected a folder, got {value!r} (an unset variable?)" in err.replace("-o/", "")
    assert not list(tmp_path.iterdir())


def test_colormap_message_lists_names(capsys):
    rc, _, err = _main(capsys, "gauss", "--colormap", "zzzzzz")
    assert rc == 2
    assert "some valid names: viridis" in err and "names in all" in err


@pytest.mark.parametrize(
    "content, message",
    [
        (None, "missing.json: no such file"),
        (b"not json at all", "not a pytest-benchmark JSON file"),
        (b"[1, 2, 3]", "not a pytest-benchmark JSON file"),
        (b'{"benchmarks": [{"extra_info": {"op": "x"}}]}', "not a pytest-benchmark JSON file"),
    ],
)
def test_bench_report_files(tmp_path, capsys, content, message):
    path = tmp_path / "missing.json"
    if content is not None:
        path = tmp_path / "r.json"
        path.write_bytes(content)
    rc, out, err = _main(capsys, "bench", "primitives", "--report", path)
    assert rc == 2 and out == ""
    _one_line_error(err, "bench")
    assert "argument --report" in err and message in err, err


def test_library_errors_are_one_line(tmp_path, capsys, monkeypatch):
    """A ClvisError from a library call (here the device choice) is one line, exit 2."""

    def no_device(*a, **k):
        raise DeviceError("no device can hold this\nsecond line of detail")

    monkeypatch.setattr(clvis.runtime, "default_queue", no_device)
    for args in (
        ["iso", "--size", "16x16"],
        ["gauss", "--size", "16x16", "--lod", "low"],
        ["render", "--points", "100", "--size", "16x16", "--quiet"],
        ["demo", "--n", "100"],
    ):
        rc, _, err = _main(capsys, *args, "--out", tmp_path / "out")
        assert rc == 2
        _one_line_error(err, args[0])
        assert "no device can hold this [more with CLVIS_DEBUG=1]" in err, err
    monkeypatch.setenv("CLVIS_DEBUG", "1")
    with pytest.raises(DeviceError):
        cli.main(["iso", "--size", "16x16", "--out", str(tmp_path / "out")])


def test_data_error_is_one_line(tmp_path, capsys):
    (tmp_path / "junk.npz").write_bytes(b"PK not really")
    rc, _, err = _main(capsys, "gauss", tmp_path / "junk.npz", "--out", tmp_path / "out")
    assert rc == 2
    _one_line_error(err, "gauss")
    assert "junk.npz" in err


def test_bare_clvis_prints_help(capsys):
    rc, out, err = _main(capsys)
    assert rc == 0 and err == ""
    assert out.startswith("usage: clvis") and "render" in out and "CLVIS_DEBUG" in out


def test_version(capsys):
    rc, out, _ = _main(capsys, "--version")
    assert rc == 0 and out == f"clvis {clvis.__version__}\n"


def test_unknown_command(capsys, tmp_path):
    """No such command: the commands, the closest one, the option meant
    (`clvis orbit`), or where a file goes (`clvis scan.las`)."""
    rc, _, err = _main(capsys, "paint")
    assert (
        rc == 2 and err.startswith("usage: clvis") and "no command 'paint'; the commands: info, demo" in err
    )
    rc, _, err = _main(capsys, "rendr", "x.las")
    assert rc == 2 and "no command 'rendr'; did you mean render?" in err
    rc, _, err = _main(capsys, "orbit", "x.las")
    assert (
        rc == 2
        and "no command 'orbit'; a turntable is an option: clvis render|iso|gauss FILE --orbit N" in err
    )
    scan, brain = tmp_path / "scan.las", tmp_path / "brain.nii.gz"
    rc, _, err = _main(capsys, str(scan))
    assert (
        rc == 2 and f"a file goes after the command: clvis view {scan}, or clvis render|gauss {scan}" in err
    )
    rc, _, err = _main(capsys, str(brain))
    assert rc == 2 and f"a file goes after the command: clvis view {brain}, or clvis iso|gauss {brain}" in err


def test_unrecognized_arguments_are_the_commands_error(capsys, tmp_path):
    """A word the command does not take is its one-line error (not clvis's
    top-level usage), with the nearest option for a misspelt one."""
    rc, _, err = _main(capsys, "render", "--sise", "10x10")
    assert rc == 2 and err.startswith("clvis render: error: unrecognized arguments: --sise"), err
    assert "did you mean --size?" in err and "usage:" not in err
    rc, _, err = _main(capsys, "iso", "a.npy", "b.npy")
    assert rc == 2 and err.startswith("clvis iso: error: unrecognized arguments: b.npy"), err
    rc, _, err = _main(capsys, "--bogus")
    assert rc == 2 and "clvis: error: unrecognized arguments: --bogus" in err


def test_broken_pipe_is_quiet(capsys, monkeypatch):
    class ClosedPipe(io.StringIO):
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(sys, "stdout", ClosedPipe())
    assert cli.main(["info"]) == 141
    assert capsys.readouterr().err == ""


def _env():
    env = dict(os.environ)
    root = str(Path(cli.__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [root, env.get("PYTHONPATH")]))
    return env


def test_info_into_head(tmp_path):
    """`clvis info | head -1`: the first line, and nothing on stderr."""
    r = subprocess.run(
        f"'{sys.executable}' -m clvis info | head -1",
        shell=True,
        cwd=tmp_path,
        env=_env(),
        capture_output=True,
        text=True,
        check=False,
    )
    assert r.stdout.startswith(f"clvis {clvis.__version__}") and r.stdout.count("\n") == 1
    assert r.stderr == ""


def test_python_m_clvis(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "clvis", "--version"],
        cwd=tmp_path,
        env=_env(),
        capture_output=True,
        text=True,
        check=False,
    )
    assert r.returncode == 0 and r.stdout == f"clvis {clvis.__version__}\n"
    r = subprocess.run(
        [sys.executable, "-m", "clvis", "iso", "--isovalue", "nan"],
        cwd=tmp_path,
        env=_env(),
        capture_output=True,
        text=True,
        check=False,
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--isovalue" in r.stderr
