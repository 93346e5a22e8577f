"""post family: small U-Nets that turn fast renders into the images a slow
renderer gives, run with onnxruntime (trained here with PyTorch: ``clvis
train``), and the classical baseline every network must beat, a push-pull
hole fill (:mod:`clvis.post.pushpull`).

Inference needs onnxruntime only; torch is imported by ``clvis train`` and
the tests that compare the exported graphs with their PyTorch modules.
"""

from .infer import MIN_SCALED_SIDE, MODELS, PRECISIONS, SCALED_SMOOTH, PostNetwork, load, resized
from .inputs import IsoPlanes
from .names import NAMES
from .pack import pack_gbuffers, pack_iso, pack_rgbda, padded_shape, unpack_rgba8
from .pushpull import pushpull

__all__ = [
    "IsoPlanes",
    "MIN_SCALED_SIDE",
    "MODELS",
    "NAMES",
    "PRECISIONS",
    "PostNetwork",
    "SCALED_SMOOTH",
    "load",
    "pack_gbuffers",
    "pack_iso",
    "pack_rgbda",
    "padded_shape",
    "pushpull",
    "resized",
    "unpack_rgba8",
]
