"""NumPy definition of clvis.raster.morton: the Morton order of a cloud."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ..morton import morton_codes

__all__ = ["morton_order"]


def morton_order(positions: npt.ArrayLike) -> np.ndarray:
    """Stable argsort of the Morton codes, uint32."""
    return np.argsort(morton_codes(positions), kind="stable").astype(np.uint32)
