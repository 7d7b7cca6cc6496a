"""hanzo-fusion: sensor fusion and SLAM (namespace package root)."""
