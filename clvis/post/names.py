"""The shipped networks' names (no import of torch or onnxruntime)."""

NAMES = ("infill", "lidar", "narvis")

#: G-buffer planes the NARVis U-Net can take by name, and their channels;
#: any other name is an attribute plane (one channel)
GBUFFER_PLANES = {"rgb": 3, "coverage": 1, "depth": 1, "vel2d": 4}
#: the default selection (the paper's Table 7 favours RGB, depth and Vel2D)
DEFAULT_GBUFFER_PLANES = ("rgb", "depth", "vel2d")


def gbuffer_channels(planes: str | tuple[str, ...] | list[str]) -> list[str]:
    """The channel layout of a plane selection: R, G, B and the coverage
    (1 where a point was drawn) always first, then the depth, then the screen
    velocity (v'x, v'y, its angle, |v'|), then any other planes (attributes)
    in the order given."""
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
    return out + [p for p in planes if p not in GBUFFER_PLANES]
