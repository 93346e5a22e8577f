"""The shipped networks' names (no import of torch or onnxruntime)."""

NAMES = ("infill", "lidar")
