"""Patch layout of a segmented point cloud: adjacency, shared borders and corners."""

from __future__ import annotations

from pde2cad.layout.adjacency import Layout, build_layout

__all__ = ["Layout", "build_layout"]
