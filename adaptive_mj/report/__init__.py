"""Turning a Trajectory into a report: metrics.py (pure functions of the arrays,
with units), plot.py (PNG figures) and video.py (MP4/GIF of the model with a ghost
of the reference)."""
