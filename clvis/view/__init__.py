"""clvis.view: an interactive, progressive viewer in the browser.

``clvis.view(obj)`` renders `obj` (a clvis.PointCloud, (N, 3) positions or a
3-D volume [z, y, x]) on the OpenCL device, serves a page at a local address
and returns a :class:`Viewer`: in Jupyter (and VS Code notebooks) it shows
inline as an IFrame of that page; elsewhere ``viewer.show()`` opens a browser
and ``viewer.wait()`` blocks until Ctrl-C. ``clvis view FILE`` is the same
from the command line.

A layer above the families (it drives the raster, iso, gauss and post
renderers): scenes.py (what is drawn, per mode), orbit.py (the camera),
schedule.py (latest-wins rendering and sending), server.py (HTTP and
WebSocket, tornado: the ``view`` extra), static/index.html (the page; no
build step).
"""

from __future__ import annotations

import html
import sys
import types
import webbrowser
from typing import Any

import numpy as np

from .orbit import Orbit
from .scenes import (
    DaskPointScene,
    DaskVolumeScene,
    Frame,
    PointScene,
    Scene,
    SparseScene,
    VolumeScene,
    scene_for,
)
from .schedule import LatestWins, Outbox
from .server import ViewServer, needs_token, token_ok

__all__ = [
    "DaskPointScene",
    "DaskVolumeScene",
    "Frame",
    "LatestWins",
    "Orbit",
    "Outbox",
    "PointScene",
    "Scene",
    "SparseScene",
    "ViewServer",
    "Viewer",
    "VolumeScene",
    "needs_token",
    "scene_for",
    "token_ok",
    "view",
]


class Viewer:
    """A running viewer: ``url``, ``server``; shows inline in a notebook.
    ``with clvis.view(obj) as v:`` closes it at the block's end."""

    def __init__(self, server: ViewServer, width: int = 960, height: int = 540) -> None:
        self.server = server
        self.width, self.height = width, height

    @property
    def url(self) -> str:
        return self.server.url

    def __repr__(self) -> str:
        return f"<clvis.view {self.server.scene.description} at {self.url}>"

    def _repr_html_(self) -> str:
        return (
            f'<iframe src="{html.escape(self.url)}" width="{self.width}" height="{self.height}" '
            'style="border: 0" allow="clipboard-write"></iframe>'
        )

    def show(self) -> bool:
        """Open the page in the default browser (False where there is none)."""
        try:
            return webbrowser.open(self.url)
        except webbrowser.Error:
            return False

    def wait(self) -> None:
        """Serve until Ctrl-C, then close."""
        try:
            self.server.thread.join()
        except KeyboardInterrupt:
            pass
        finally:
            self.close()

    def close(self) -> None:
        self.server.close()

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def view(
    obj: Any,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    token: str | None = None,
    width: int = 960,
    height: int = 540,
    interactive_scale: float = 0.5,
    max_pages: int = 8,
    **scene_options: Any,
) -> Viewer:
    """Serve an interactive view of `obj` and return its :class:`Viewer`.

    obj: a clvis.PointCloud, (N, 3) positions, a 3-D volume [z, y, x] (with
    ``spacing``, ``origin``, ``isovalue``, ``rate``), a clvis.Volume
    (read_volume's: its spacing and origin), a clvis.SparseVolume
    (read_vdb's: its Gaussians, ``colormap``; its isosurface, ``isovalue``,
    ``rate``), a VTK dataset (a pyvista
    mesh, point set or image: clvis.from_vtk), an Open3D point cloud or
    triangle mesh (clvis.from_open3d) or a Scene. host: the
    interface to listen on (127.0.0.1; any other needs the printed token),
    port 0: a free one. width x height: the notebook frame's size.
    max_pages: the pages (tabs) served at once, each with its own camera and
    size (the settings are shared). model_dir (a scene option): where the
    network modes' models are (``clvis train --out``; default the package's).
    """
    for name, side in (("width", width), ("height", height)):
        if isinstance(side, bool) or not isinstance(side, (int, np.integer)) or side < 1:
            raise ValueError(f"{name}: the notebook frame's size, expected a positive integer, got {side!r}")
    width, height = int(width), int(height)
    scene = scene_for(obj, **scene_options)
    server = ViewServer(
        scene,
        host,
        port,
        token=token,
        interactive_scale=interactive_scale,
        size=(width, height),
        max_pages=max_pages,
    )
    return Viewer(server, width, height)


class _CallableModule(types.ModuleType):
    """``clvis.view(obj)`` calls :func:`view`; ``clvis.view.Viewer`` etc. still work."""

    def __call__(self, obj: Any, **kwargs: Any) -> Viewer:
        return view(obj, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
