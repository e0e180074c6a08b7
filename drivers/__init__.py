"""Hardware drivers: V4L2 capture, serial protocols and links, USB discovery (installed as rigctl.drivers)."""
