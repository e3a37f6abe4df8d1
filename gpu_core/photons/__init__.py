"""Photon maps: photon tracing, the point kd-tree with kNN and density estimation."""

from .point_tree import FILTERS, PointTree
from .trace import PhotonMaps, trace_photon_maps

__all__ = ["FILTERS", "PhotonMaps", "PointTree", "trace_photon_maps"]
