"""clvis train's output (a table, not dicts of 16-digit floats), its held-out
rows (a frame counted once when one pass reaches two completions), and the
extra clvis train and clvis bench name when what they need is missing (the
missing modules simulated)."""

import importlib.util
import re

import numpy as np
import pytest

from clvis import cli
from clvis.cli.train import held_out_table


def _main(capsys, *args):
    try:
        rc = cli.main([*map(str, args)])
    except SystemExit as e:
        rc = e.code
    out, err = capsys.readouterr()
    return rc, out, err


def test_train_without_torch_names_the_extra(monkeypatch, tmp_path, capsys):
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "torch" else real(name, *a)
    )
    rc, out, err = _main(capsys, "train", "infill", "--steps", "1", "--out", tmp_path)
    assert rc == 2 and out == ""
    assert "pip install '.[train]'" in err and "(torch missing)" in err
    assert err.count("\n") == 1
    assert not list(tmp_path.iterdir())


def test_bench_without_pytest_names_the_extra(monkeypatch, capsys):
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "pytest" else real(name, *a)
    )
    rc, out, err = _main(capsys, "bench", "primitives")
    assert rc == 2
    assert "pytest not installed" in err and "pip install '.[test]'" in err
    assert "running:" not in out  # refused before starting the suite


def test_held_out_table_is_a_table():
    rows = {
        f"completion {c}": {
            "input": {"psnr": 21.123456789012345, "ssim": 0.8123456789},
            "pushpull": {"psnr": 19.5, "ssim": 0.7},
            "network": {"psnr": 24.25, "ssim": 0.9},
        }
        for c in (0.85, 0.9)
    }
    text = held_out_table(rows)
    lines = text.splitlines()
    assert len(lines) == 3 and "push-pull dB" in lines[0] and "vs push-pull" in lines[0]
    assert re.search(
        r"completion 0\.85\s+21\.12\s+0\.812\s+19\.50\s+0\.700\s+24\.25\s+0\.900\s+\+3\.13\s+\+4\.75", text
    )
    assert "{" not in text and "123456" not in text


def test_a_frame_two_completions_share_is_scored_once():
    pytest.importorskip("torch")
    from clvis.training import train

    class Frame:
        def __init__(self, masks):
            self.active = masks

    a, b = np.zeros((4, 4), bool), np.zeros((4, 4), bool)
    a[0] = True
    b[0, :2] = True
    same = Frame({0.85: a, 0.9: a, 0.95: b})  # one pass went past 0.85 and 0.90
    apart = Frame({0.85: a, 0.9: b, 0.95: np.zeros((4, 4), bool)})
    notes = []
    got = train._distinct_frames([same, apart], (0.85, 0.9, 0.95), notes.append)
    assert got[0.85] == [same, apart] and got[0.9] == [apart] and got[0.95] == [same, apart]
    assert len(notes) == 1 and "1 of 2 frames" in notes[0]
    got = train._distinct_frames([same], (0.85, 0.9), notes.append)
    assert got[0.9] == [] and "no row" in notes[-1]


def _scores(inp, pp, net):
    return {k: {"psnr": v, "ssim": 0.5} for k, v in (("input", inp), ("pushpull", pp), ("network", net))}


def test_demo_gains_are_over_the_input_and_the_best_baseline():
    """The demo's narvis and lidar lines: push-pull floods the background and
    scores below the raw input there, so a gain over push-pull alone flatters."""
    from clvis.cli.demo_post import _line, gains

    assert gains(_scores(20.0, 17.0, 22.5)) == (2.5, 2.5, "input")
    assert gains(_scores(20.0, 26.0, 26.5)) == (6.5, 0.5, "push-pull")
    line = _line("narvis", _scores(20.0, 17.0, 19.0), 0.01)
    assert "(-1.0 dB over the input, -1.0 dB over the best baseline, input)" in line
    # narvis-scan: the classical splat of the radius plane is a third baseline
    s = {**_scores(20.0, 17.0, 26.0), "splat": {"psnr": 24.5, "ssim": 0.7}}
    assert gains(s) == (6.0, 1.5, "splat")
    assert gains({**s, "splat": {"psnr": 16.0, "ssim": 0.4}}) == (6.0, 6.0, "input")
    line = _line("narvis-scan", s, 0.01)
    assert "splat  24.5 dB / 0.700" in line and "1.5 dB over the best baseline, splat)" in line
