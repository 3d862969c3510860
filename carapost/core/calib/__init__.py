"""Calibration and 3D initialisation: brim solve, seeds, Initialize 3D, bundle adjustment.

Pure functions over arrays and cameras; each operation on a project returns a
command that applies its result, so the GUI, the API and the CLI share undo.
"""
