"""Inverse rendering: totem pose from masks, and the joint fit of a radiance grid and
the totem centres with Dr.Jit gradients (camera frame = OpenCV, metres)."""
