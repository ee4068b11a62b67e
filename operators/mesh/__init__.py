# SPDX-License-Identifier: GPL-3.0-or-later
"""Vertex-position runs: mesh read/write, the runner that prepares, computes and writes a
mesh, the reference shape of target "reference", and the mesh operators (untangle, pins,
quality)."""
