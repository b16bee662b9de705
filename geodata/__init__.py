"""geodata: raw triangle meshes to exact geodesic (and biharmonic) training data in zarr stores."""
from geodata.mesh import Mesh, MeshError

__all__ = ["Mesh", "MeshError"]
__version__ = "0.2.0"
