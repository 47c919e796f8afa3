"""regrasp: pick-and-place planning with two-hand regrasping for dual-arm robots."""

__version__ = "0.1.0"
