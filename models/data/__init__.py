"""Datasets for the crowd-density model."""
