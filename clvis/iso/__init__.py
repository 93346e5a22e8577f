"""iso family: progressive isosurface raycasting over ZFP-compressed volumes
(Dyken, Usher, Kumar, TVCG 2024). Module ↔ kernel: zfp.py ↔ zfp.cl,
macrocell.py ↔ macrocell.cl, traverse.py ↔ traverse.cl, cache.py ↔ cache.cl,
raytrace.py ↔ raytrace.cl, surface.py ↔ surface.cl (colouring
the surface: a second field at the hits, several isovalues), render.py ↔ pass.cl (the pass loop; ``pass`` is a
Python keyword)."""

from . import zfp
from .cache import BlockCache, mark_blocks
from .macrocell import MacrocellGrids, macrocell_grids
from .raytrace import raytrace_blocks
from .render import CANDIDATES, IsoImage, IsoRenderer
from .surface import SURFACE_COLOR, color_surface, composite, sample_hits, surface_colors
from .traverse import init_rays, macro_traverse
from .zfp import ZfpVolume

__all__ = [
    "CANDIDATES",
    "BlockCache",
    "IsoImage",
    "IsoRenderer",
    "MacrocellGrids",
    "SURFACE_COLOR",
    "ZfpVolume",
    "color_surface",
    "composite",
    "init_rays",
    "macro_traverse",
    "macrocell_grids",
    "mark_blocks",
    "raytrace_blocks",
    "sample_hits",
    "surface_colors",
    "zfp",
]
