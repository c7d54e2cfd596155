"""Synthetic totem-protected scenes (Mitsuba 3), the scene folder, manipulations."""
