"""Per-scene refinement of the reconstruction: the field fitted to the capture's views after the feed-forward pass."""
