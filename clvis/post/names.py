"""The shipped networks' names (no import of torch or onnxruntime)."""

NAMES = ("infill", "lidar", "narvis", "narvis-scan")

#: G-buffer planes the NARVis U-Net can take by name, and their channels;
#: any other name is an attribute plane (one channel)
GBUFFER_PLANES = {"rgb": 3, "coverage": 1, "depth": 1, "vel2d": 4, "radius": 1}
#: the default selection (the paper's Table 7 favours RGB, depth and Vel2D)
DEFAULT_GBUFFER_PLANES = ("rgb", "depth", "vel2d")
#: narvis-scan's selection (clouds without velocity: LAS/LAZ/PLY scans): the
#: colour, the depth and the splat radius in pixels (GBuffers.radius_px, the
#: points' world radius, their mean 4-NN distance, projected by the
#: rasterizer's resolve)
SCAN_GBUFFER_PLANES = ("rgb", "depth", "radius")


def gbuffer_channels(planes: str | tuple[str, ...] | list[str]) -> list[str]:
    """The channel layout of a plane selection: R, G, B and the coverage
    (1 where a point was drawn) always first, then the depth, then the screen
    velocity (v'x, v'y, its angle, |v'|), then the splat radius in pixels
    ("radius": GBuffers.radius_px), then any other planes (attributes) in the
    order given."""
    if isinstance(planes, str):
        planes = (planes,)
    planes = tuple(planes)
    if not all(isinstance(p, str) and p for p in planes):
        raise TypeError(f"planes: expected plane names, got {planes!r}")
    if len(set(planes)) != len(planes):
        raise ValueError(f"planes: {list(planes)} names one twice")
    if "rgb" not in planes:
        raise ValueError(f"planes: {list(planes)} lacks 'rgb' (the network always takes the colours)")
    out = ["r", "g", "b", "coverage"]
    if "depth" in planes:
        out.append("depth")
    if "vel2d" in planes:
        out += ["vel_x", "vel_y", "vel_angle", "vel_speed"]
    if "radius" in planes:
        out.append("radius_px")
    return out + [p for p in planes if p not in GBUFFER_PLANES]
