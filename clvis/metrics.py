"""Image metrics the post networks are scored by (PSNR and SSIM through
scikit-image), importable without torch: ``clvis eval``, ``clvis train``
and the tests all use these."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["metrics"]


def metrics(output: np.ndarray, target: np.ndarray) -> dict[str, float]:
    """PSNR (dB; inf where equal) and SSIM of two (H, W, 3) float images in
    [0, 1] (values outside are clipped), through scikit-image."""
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    o = np.clip(np.asarray(output), 0, 1).astype(np.float64)
    t = np.clip(np.asarray(target), 0, 1).astype(np.float64)
    if o.shape != t.shape or o.ndim != 3 or o.shape[2] != 3:
        raise ValueError(f"metrics: expected two (H, W, 3) images, got {o.shape} and {t.shape}")
    psnr = float(peak_signal_noise_ratio(t, o, data_range=1.0)) if not np.array_equal(o, t) else math.inf
    ssim = float(structural_similarity(t, o, data_range=1.0, channel_axis=2))
    return {"psnr": psnr, "ssim": ssim}
