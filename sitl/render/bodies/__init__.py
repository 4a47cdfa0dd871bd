"""MakeHuman people for the SITL camera: asset readers, rig and skinning, the packed library, seeded figures.

The data (``data/bodies.npz``) is packed from MakeHuman's CC0 assets by ``scripts/pack_bodies.py``; see
``docs/sitl.md`` ("People that look like people").
"""
