"""Takes on disk: a folder with a versioned manifest, per-camera raw essence and a per-frame index."""
