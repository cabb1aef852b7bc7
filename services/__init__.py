"""The Floorplan-Jigsaw algorithm: pure functions over numpy arrays, no I/O."""
