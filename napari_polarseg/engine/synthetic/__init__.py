"""Synthetic polarisation scenes rendered from physics, with their ground truth."""
