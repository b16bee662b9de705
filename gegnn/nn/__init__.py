"""Graph layers of GeGnn (pure torch)."""
from .blocks import ResBlock, ResBlocks
from .geoconv import GeoConv, aggregate
from .geopool import GeoPool, GeoUnpool, Hierarchy, build_hierarchy, geo_clusters, pool_features, pool_graph

__all__ = ["GeoConv", "aggregate", "GeoPool", "GeoUnpool", "Hierarchy", "build_hierarchy", "geo_clusters",
           "pool_features", "pool_graph", "ResBlock", "ResBlocks"]
