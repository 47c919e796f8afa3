"""Grasp synthesis and scoring for single-hand grasps."""
