"""Offline roadmaps: local planner, Vis-PRM, Super Graph composition (Saut et al. 2010, §V-A)."""
