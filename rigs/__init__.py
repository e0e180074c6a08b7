"""Rig files shipped with rigctl (data only; installed as rigctl.rigs)."""
