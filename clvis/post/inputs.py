"""What each shipped network reads from its input, as ``typing.Protocol``
classes: post takes a renderer's output by the planes it has and never
imports the renderers (the family rule, tests/test_layout.py).

- :class:`IsoImageLike`: the in-fill network's (``clvis.iso.IsoImage``);
- :class:`FilteredImageLike`: the LiDAR network's (``clvis.raster.FilteredImage``;
  the network also takes the ``rgbda`` plane itself);
- :class:`GBuffersLike`: the NARVis network's (``clvis.raster.GBuffers``).

Each plane is a :data:`Plane`, numpy or device (``host=False`` results), as
the renderers' result dataclasses declare them; any object with these
attributes will do. mypy checks the call sites (``PostNetwork.__call__``,
the specs' and :func:`clvis.post.pack.pack_gbuffers`'s inputs); the checks
at run time (a missing plane, a wrong shape or dtype) stay where they were,
in :mod:`clvis.post.specs` and :mod:`clvis.post.pack`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol, TypeAlias

import numpy as np
import pyopencl.array as cla

__all__ = [
    "FilteredImageLike",
    "GBuffersLike",
    "IsoImageLike",
    "IsoPlanes",
    "LidarInput",
    "Plane",
    "PostInput",
]

#: a plane on the host or on the device
Plane: TypeAlias = np.ndarray | cla.Array


class IsoImageLike(Protocol):
    """The in-fill network's input: an iso image's shaded colour and masks.

    A model of 6 planes also reads ``candidates`` ((H, W) uint8, the
    candidate blocks left on each running ray); one of 7 the frame's crossing
    rate too, from ``stats["items_per_pass"]`` (the render's pass items) or
    a ``crossing_rate`` attribute (clvis.post.specs.image_crossing_rate); one
    of 8 the candidates, ``t`` and ``next_t`` ((H, W) float32: a finished
    hit's ray parameter, where a running ray's next candidate block begins).
    IsoRenderer's IsoImage has all of them."""

    @property
    def rgba(self) -> Plane:
        """(H, W, 4) float32, the shaded surface (alpha unused)."""
        ...

    @property
    def hit(self) -> Plane:
        """(H, W) bool or uint8: a ray met the surface."""
        ...

    @property
    def active(self) -> Plane:
        """(H, W) bool or uint8: the ray is still running."""
        ...


@dataclass
class IsoPlanes:
    """An IsoImageLike of planes you hold (the guard's reduced inputs, the
    held-out suite's frames, a caller's own): ``rgba``, ``hit``, ``active``;
    ``candidates`` for a 6-, 7- or 8-plane model; ``crossing_rate`` for a
    7-plane one (clvis.post.pack.crossing_rate: it stands for an IsoImage's
    ``stats``); ``t`` and ``next_t`` for an 8-plane one (IsoImage's)."""

    rgba: Plane
    hit: Plane
    active: Plane
    candidates: Plane | None = None
    crossing_rate: float | None = None
    t: Plane | None = None
    next_t: Plane | None = None


class FilteredImageLike(Protocol):
    """The LiDAR network's input: a depth-filtered point image."""

    @property
    def rgbda(self) -> Plane:
        """(H, W, 5) float32 [r, g, b, depth, alpha]."""
        ...


class GBuffersLike(Protocol):
    """The NARVis network's input: rasterizer G-buffers (the planes its card
    names are read; a plane it does not name may be None)."""

    @property
    def index(self) -> Plane:
        """(H, W) uint32, 0xFFFFFFFF where empty."""
        ...

    @property
    def rgba(self) -> Plane:
        """(H, W, 4) uint8."""
        ...

    @property
    def depth(self) -> Plane:
        """(H, W) float32."""
        ...

    @property
    def attributes(self) -> Mapping[str, Plane] | None:
        """name -> (H, W) plane."""
        ...

    @property
    def vel2d(self) -> Plane | None:
        """(H, W, 2) float32 screen velocity."""
        ...

    @property
    def vel_angle(self) -> Plane | None:
        """(H, W) float32."""
        ...

    @property
    def vel_speed(self) -> Plane | None:
        """(H, W) float32."""
        ...


#: what the LiDAR network takes: a FilteredImage or its rgbda plane
LidarInput: TypeAlias = FilteredImageLike | Plane
#: what some shipped network takes (PostNetwork's call; its spec checks which)
PostInput: TypeAlias = IsoImageLike | FilteredImageLike | GBuffersLike | Plane
