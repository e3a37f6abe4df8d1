"""Photon maps: emission in Cycles' units and tracing into the global and
caustic maps (each a point kd-tree, gpu_core/accel/point_tree.py)."""

from .trace import PhotonMaps, trace_photon_maps

__all__ = ["PhotonMaps", "trace_photon_maps"]
