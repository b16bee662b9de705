"""Graph layers of GeGnn (pure torch)."""
from .blocks import ResBlock, ResBlocks
from .geoconv import GeoConv, cpu_inference
from .geopool import GeoPool, GeoUnpool, Hierarchy, build_hierarchy, geo_clusters, pool_features, pool_graph
from .scatter import ScatterMax, aggregate, scatter_count, scatter_mean

__all__ = ["GeoConv", "cpu_inference", "aggregate", "scatter_count", "scatter_mean", "ScatterMax", "GeoPool", "GeoUnpool",
           "Hierarchy", "build_hierarchy", "geo_clusters", "pool_features", "pool_graph", "ResBlock", "ResBlocks"]
