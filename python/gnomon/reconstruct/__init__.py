"""Reconstruction, from tracked shadow times and a light model to one fused depth map: each edge's
times, planes and depths with σ (:mod:`~gnomon.reconstruct.edges`), a fast sweep re-timed between its
isochrones (:mod:`~gnomon.reconstruct.retiming`), the edges (or two scans) fused
(:mod:`~gnomon.reconstruct.fusion`, :mod:`~gnomon.reconstruct.fused`), and what the report says of it
(:mod:`~gnomon.reconstruct.report`).
"""

from gnomon.reconstruct.edges import EdgeResult, edge_time_maps, reconstruct_edges
from gnomon.reconstruct.fused import FusedMaps, fuse_edges
from gnomon.reconstruct.fusion import fuse_depths
from gnomon.reconstruct.report import scan_report
from gnomon.reconstruct.retiming import retime_between_isochrones

__all__ = [
    "EdgeResult", "FusedMaps", "edge_time_maps", "fuse_depths", "fuse_edges", "reconstruct_edges",
    "retime_between_isochrones", "scan_report",
]
