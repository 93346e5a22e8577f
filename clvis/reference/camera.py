"""NumPy reference of the camera rays kernels build from
clvis.camera.ray_buffer (kernels_cl/include/clvis/camera.h, clvis_camera_ray):
the same float32 operations in the same order."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["camera_rays"]


def camera_rays(cam: npt.ArrayLike, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions (H*W, 3) float32 from the 22-float ray buffer."""
    cam = np.asarray(cam, np.float32)
    py, px = np.mgrid[0:height, 0:width]
    u = (px.ravel().astype(np.float32) + np.float32(0.5))[:, None]
    v = (py.ravel().astype(np.float32) + np.float32(0.5))[:, None]
    o = (cam[0:3] + u * cam[3:6]) + v * cam[6:9]
    dd = (cam[9:12] + u * cam[12:15]) + v * cam[15:18]
    length = np.sqrt((dd[:, 0] * dd[:, 0] + dd[:, 1] * dd[:, 1]) + dd[:, 2] * dd[:, 2])
    return o, dd / length[:, None]
