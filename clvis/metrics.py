"""Image metrics the post networks are scored by (PSNR and SSIM through
scikit-image), importable without torch: ``clvis eval``, ``clvis train``
and the tests all use these."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["as_picture", "metrics"]


def metrics(output: np.ndarray, target: np.ndarray) -> dict[str, float]:
    """PSNR (dB; inf where equal) and SSIM of two (H, W, 3) images, through
    scikit-image: floats in [0, 1] (values outside are clipped) or uint8
    pictures (as the networks and renderers return them: 0..255, scaled by
    1/255), each on its own; other types are refused."""
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    o, t = _unit("output", output), _unit("target", target)
    if o.shape != t.shape or o.ndim != 3 or o.shape[2] != 3:
        hint = " (an RGBA picture: pass [..., :3])" if o.shape[-1:] == (4,) or t.shape[-1:] == (4,) else ""
        raise ValueError(f"metrics: expected two (H, W, 3) images, got {o.shape} and {t.shape}{hint}")
    psnr = float(peak_signal_noise_ratio(t, o, data_range=1.0)) if not np.array_equal(o, t) else math.inf
    ssim = float(structural_similarity(t, o, data_range=1.0, channel_axis=2))
    return {"psnr": psnr, "ssim": ssim}


def _unit(name: str, image: np.ndarray) -> np.ndarray:
    """`image` as float64 in [0, 1]: uint8 scaled by 1/255, real floats clipped."""
    a = np.asarray(image)
    if a.dtype == np.uint8:
        return a.astype(np.float64) / 255.0
    if a.dtype.kind != "f":
        raise TypeError(
            f"metrics: {name} of dtype {a.dtype}; expected floats in [0, 1] or a uint8 picture (0..255)"
        )
    return np.clip(a, 0, 1).astype(np.float64)


def as_picture(rgb: np.ndarray) -> np.ndarray:
    """A float image as the 8-bit picture a user gets (clipped to 0..1,
    rounded to 1/255, NaN as 0), as a network's call returns its own
    (clvis.post.infer): ``clvis eval`` and ``clvis iso --compare`` score
    every method on what it shows."""
    v = np.nan_to_num(np.clip(np.asarray(rgb, np.float32), np.float32(0), np.float32(1)), nan=0.0)
    return np.rint(v * np.float32(255)) / np.float32(255)
