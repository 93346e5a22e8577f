"""Edits of a model card loaded with post.load(directory=...): each loads and
runs, or raises a clvis error naming the card or its file (never a
ValueError/TypeError/KeyError/AttributeError or onnxruntime's own error)."""

import json
import shutil

import numpy as np
import pytest

from clvis import post
from clvis.errors import ClvisError
from clvis.post.infer import MODELS

pytest.importorskip("onnxruntime")

BAD = [None, "x", -1, 0, 3, 7, 2**40, 1.5, True, [], {}]
EDITS = (
    [("stride", v) for v in BAD + [64, 2048]]
    + [("channels_in", v) for v in BAD + [4, 6]]
    + [("channels_out", v) for v in BAD + [4]]
    + [("files", v) for v in (None, [], {"fp32": None}, {"fp32": "lidar.onnx"}, {"fp32": {}})]
    + [("files.fp32.file", v) for v in (None, 5, "", "../lidar.onnx", "lidar.int8.onnx", [])]
    + [("files.fp32.sha256", v) for v in (None, 5, "0" * 64)]
    + [("architecture", v) for v in (None, [], "x", {"planes": 5}, {"planes": [1, 2]})]
)


def _edit(card, key, value):
    parts = key.split(".")
    d = card
    for p in parts[:-1]:
        d = d[p]
    d[parts[-1]] = value


def _edited_copy(tmp_path, name, key, value):
    """The shipped model `name` copied into tmp_path with its card's `key` set
    to `value`."""
    for f in MODELS.glob(f"{name}*"):
        shutil.copy(f, tmp_path / f.name)
    card = json.loads((tmp_path / f"{name}.json").read_text())
    _edit(card, key, value)
    (tmp_path / f"{name}.json").write_text(json.dumps(card))


@pytest.mark.parametrize("key,value", EDITS, ids=[f"{k}={v!r}"[:40] for k, v in EDITS])
def test_edited_card_loads_and_runs_or_raises_a_clvis_error(tmp_path, key, value):
    _edited_copy(tmp_path, "lidar", key, value)
    try:
        net = post.load("lidar", directory=tmp_path)
        out = net(np.zeros((40, 24, 5), np.float32))
        assert out.shape == (40, 24, 4)
    except ClvisError as e:
        assert str(tmp_path) in str(e) or str(e).startswith("lidar: no fp32 variant"), e


# the NARVis card's "head" (issue 28: its graph stops at the logits): an edit
# that no longer describes the graph, or a head clvis.post.kpn cannot apply,
# is a DataError naming the card; removing the head is one (the graph's two
# outputs are not an image)
HEAD_EDITS = (
    [("head", v) for v in (None, 5, [], {}, {"kind": "unet"})]
    + [
        ("head.kernels", v)
        for v in (None, "x", [], [[2, 1]], [[3, 3]], [[3, 1]], [[5, 1], [3, 2], [3, 4], [3, 8]])
    ]
    + [("head.depth_select", v) for v in (None, 1, False)]
    + [("head.outputs", v) for v in (None, ["image"], ["nearness", "logits"])]
    + [("head.depth_scale", v) for v in ("x", None, -1.0, 1e400)]
    + [("head.logit_bound", v) for v in ("x", 0.0, -6.0)]
)


@pytest.mark.parametrize("key,value", HEAD_EDITS, ids=[f"{k}={v!r}"[:40] for k, v in HEAD_EDITS])
def test_edited_narvis_head_raises_a_clvis_error(tmp_path, key, value):
    _edited_copy(tmp_path, "narvis", key, value)
    with pytest.raises(ClvisError) as e:
        post.load("narvis", directory=tmp_path)
    assert str(tmp_path) in str(e.value), e.value


def _lidar_folder_with(folder, graph):
    """The shipped lidar model copied into `folder` with `graph` (an onnx
    GraphProto) as its lidar.onnx and the card's sha256 made to match; the
    card (a dict) to edit further, written back as it is now."""
    import onnx
    from onnx import helper

    from clvis.post.infer import sha256

    for f in MODELS.glob("lidar*"):
        shutil.copy(f, folder / f.name)
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), folder / "lidar.onnx")
    card = json.loads((folder / "lidar.json").read_text())
    card["files"]["fp32"]["sha256"] = sha256(folder / "lidar.onnx")
    (folder / "lidar.json").write_text(json.dumps(card))
    return card


def test_narvis_head_edits_that_keep_the_graph_load(tmp_path):
    """depth_scale and logit_bound are the head's own numbers: a card may
    change them (the graph is the same) and the head follows."""
    for f in MODELS.glob("narvis*"):
        shutil.copy(f, tmp_path / f.name)
    card = json.loads((tmp_path / "narvis.json").read_text())
    card["head"]["depth_scale"], card["head"]["logit_bound"] = 10.0, 4.0
    (tmp_path / "narvis.json").write_text(json.dumps(card))
    net = post.load("narvis", directory=tmp_path)
    assert net.head is not None and (net.head.depth_scale, net.head.logit_bound) == (10.0, 4.0)


def test_graph_that_loads_but_fails_when_run_raises_a_clvis_error(tmp_path):
    # a graph that matches its card (one input of 5 channels, one output of 3) and
    # loads, but whose first run fails (a Reshape to a fixed 3 x 3): onnxruntime's
    # own error escaped from the first call
    pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    consts = [
        helper.make_tensor("starts", TensorProto.INT64, [1], [0]),
        helper.make_tensor("ends", TensorProto.INT64, [1], [3]),
        helper.make_tensor("axes", TensorProto.INT64, [1], [1]),
        helper.make_tensor("shape", TensorProto.INT64, [4], [1, 3, 3, 3]),
    ]
    graph = helper.make_graph(
        [
            helper.make_node("Slice", ["planes", "starts", "ends", "axes"], ["rgb"]),
            helper.make_node("Reshape", ["rgb", "shape"], ["image"]),
        ],
        "fails_when_run",
        [helper.make_tensor_value_info("planes", TensorProto.FLOAT, [1, 5, "height", "width"])],
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, "height", "width"])],
        consts,
    )
    _lidar_folder_with(tmp_path, graph)
    net = post.load("lidar", directory=tmp_path)
    with pytest.raises(ClvisError, match=r"lidar\.onnx: onnxruntime failed running it"):
        net(np.zeros((40, 24, 5), np.float32))


@pytest.mark.parametrize("other,name", [("lidar", "infill"), ("narvis-scan", "narvis"), ("narvis", "lidar")])
def test_another_networks_model_copied_in_is_refused(tmp_path, other, name):
    # lidar's card and graph saved as infill.json / infill.onnx loaded and ran
    # on infill's 5-channel pack: a picture of garbage, no error (clvis eval
    # infill --model-dir scored it 20 dB under push-pull and exited 0)
    for f in MODELS.glob(f"{other}.*"):
        shutil.copy(f, tmp_path / f.name.replace(other, name, 1))
    with pytest.raises(ClvisError, match=f"model card is for '{other}', not '{name}'"):
        post.load(name, directory=tmp_path)


def test_card_without_a_name_of_other_channels_out_is_refused(tmp_path):
    for f in MODELS.glob("lidar.*"):
        shutil.copy(f, tmp_path / f.name.replace("lidar", "infill", 1))
    card = json.loads((tmp_path / "infill.json").read_text())
    del card["name"]
    (tmp_path / "infill.json").write_text(json.dumps(card))
    with pytest.raises(ClvisError, match="'channels_out' is 3; infill writes 4"):
        post.load("infill", directory=tmp_path)


def test_a_failing_graph_leaves_stderr_to_the_clvis_error(tmp_path, capfd):
    """onnxruntime logged its own coloured warning (a graph whose declared
    output shape is not its computed one) and error lines on stderr before
    clvis's one-line error."""
    pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    graph = helper.make_graph(
        [helper.make_node("Concat", ["planes", "planes"], ["image"], axis=1)],  # 10 channels, not 3
        "concat",
        [helper.make_tensor_value_info("planes", TensorProto.FLOAT, [1, 5, "height", "width"])],
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, "height", "width"])],
    )
    _lidar_folder_with(tmp_path, graph)
    capfd.readouterr()
    net = post.load("lidar", directory=tmp_path)
    with pytest.raises(ClvisError, match=r"lidar\.onnx: onnxruntime failed running it"):
        net(np.zeros((40, 24, 5), np.float32), guard=False)
    assert "onnxruntime" not in capfd.readouterr().err


def test_a_graph_and_card_of_channels_its_pack_does_not_write_are_refused(tmp_path):
    """A graph of 6 input channels with a card saying so loaded as lidar (whose
    pack writes 5): the call failed with pack's ValueError ("out: expected
    shape (1, 5, ...)"), not a clvis error naming the card."""
    pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    consts = [
        helper.make_tensor("starts", TensorProto.INT64, [1], [0]),
        helper.make_tensor("ends", TensorProto.INT64, [1], [3]),
        helper.make_tensor("axes", TensorProto.INT64, [1], [1]),
    ]
    graph = helper.make_graph(
        [helper.make_node("Slice", ["planes", "starts", "ends", "axes"], ["image"])],
        "six",
        [helper.make_tensor_value_info("planes", TensorProto.FLOAT, [1, 6, "height", "width"])],
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, "height", "width"])],
        consts,
    )
    card = _lidar_folder_with(tmp_path, graph)
    card["channels_in"] = 6
    (tmp_path / "lidar.json").write_text(json.dumps(card))
    with pytest.raises(ClvisError, match="'channels_in' is 6; lidar takes 5"):
        post.load("lidar", directory=tmp_path)


def test_narvis_card_planes_must_give_its_channels(tmp_path):
    for f in MODELS.glob("narvis.*"):
        shutil.copy(f, tmp_path / f.name)
    card = json.loads((tmp_path / "narvis.json").read_text())
    card["architecture"]["planes"] = ["rgb", "depth", "radius"]  # 6 channels; the graph takes 10
    (tmp_path / "narvis.json").write_text(json.dumps(card))
    with pytest.raises(
        ClvisError, match=r"'channels_in' is 10; narvis with planes \['rgb', 'depth', 'radius'\] takes 6"
    ):
        post.load("narvis", directory=tmp_path)
