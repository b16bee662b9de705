"""Write random tubular shapes of geodata.zoo (tori, bent tubes, helices, torus knots) as OBJ files, the
training data's shapes whose geodesics wrap round saddle regions (pipelines/landmark/ship.sh):

    python pipelines/landmark/zoo_meshes.py OUT_DIR COUNT [SEED]
"""
import sys
from pathlib import Path

import trimesh

from geodata.zoo import zoo_variants

out, count = Path(sys.argv[1]), int(sys.argv[2])
seed = int(sys.argv[3]) if len(sys.argv) > 3 else 0
out.mkdir(parents=True, exist_ok=True)
for name, v, f in zoo_variants(count, seed):
    trimesh.Trimesh(v, f, process=False).export(out / f"{name}.obj")
print(f"{count} shapes in {out}")
