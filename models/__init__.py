"""Density models: data, training and evaluation (training-side code; the drone needs none of it)."""
